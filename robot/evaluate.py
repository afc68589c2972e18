"""Table-I-style evaluation: simulate every world x seed, score them as one set, tabulate and plot.

The error ratio uses T_avg over all the worlds evaluated together (SPEC §3), so a table over
room1..room4 is comparable with the paper's Table I. Figures follow the paper's Figures 7 (each
map beside its truth) and 8 (scores against the number of non-vacant cells).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from robot.config import SimNoise
from robot.engine import StepResult
from robot.errors import WorldError
from robot.grid import FREE, OCCUPIED, GridSpec
from robot.mapio import atomic_write_bytes
from robot.metrics import MapMetrics, score_many
from robot.runner import RunResult, simulate, write_run_outputs
from robot.settings import RunConfig, load_run_config
from robot.world import World, load_world

# Table columns: (key, heading, format, which seed is the worst case)
COLUMNS: tuple[tuple[str, str, str, Callable[[Sequence[float]], float]], ...] = (
    ("cell_errors", "errors E", "{:.1f}", max),
    ("error_ratio", "error ratio", "{:.4f}", max),
    ("precision", "precision", "{:.4f}", min),
    ("recall", "recall", "{:.4f}", min),
    ("f1", "F1", "{:.4f}", min),
    ("xy_cm", "xy err cm", "{:.1f}", max),
    ("theta_deg", "theta err deg", "{:.2f}", max),
)


@dataclass(frozen=True)
class RunScore:
    """One simulated run, scored within the evaluated set (T_avg over all its worlds)."""

    world: str
    seed: int
    metrics: MapMetrics
    xy_cm: float  # final pose error [cm]
    theta_deg: float  # final heading error [deg]
    steps: int
    sim_time_s: float
    wall_time_s: float
    terminated_by: str

    def value(self, key: str) -> float:
        if key in ("xy_cm", "theta_deg"):
            return float(getattr(self, key))
        return float(getattr(self.metrics, key))

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["metrics"] = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.metrics.as_dict().items()}
        for key in ("xy_cm", "theta_deg", "sim_time_s", "wall_time_s"):
            out[key] = round(out[key], 3)
        return out


@dataclass(frozen=True)
class WorldRow:
    """One world's line of the table: the mean and the worst case over its seeds."""

    world: str
    rows: int
    cols: int
    total_cells: int  # T
    non_vacant: int  # N
    mean: dict[str, float]
    worst: dict[str, float]


@dataclass
class Evaluation:
    runs: list[RunScore]
    first_maps: dict[str, RunResult]  # each world's seed-0 run, for the figures
    t_avg: float
    resolution: float
    mapper: str
    wall_time_s: float

    def table(self) -> list[WorldRow]:
        rows = []
        for name in dict.fromkeys(r.world for r in self.runs):
            runs = [r for r in self.runs if r.world == name]
            grid = self.first_maps[name].grid
            rows.append(
                WorldRow(
                    world=name,
                    rows=grid.rows,
                    cols=grid.cols,
                    total_cells=runs[0].metrics.total_cells,
                    non_vacant=runs[0].metrics.non_vacant,
                    mean={key: float(np.mean([r.value(key) for r in runs])) for key, *_ in COLUMNS},
                    worst={key: float(worst([r.value(key) for r in runs])) for key, _, _, worst in COLUMNS},
                )
            )
        return rows

    def overall(self) -> dict[str, float]:
        """The mean over every run (each world weighs the same: every world has the same seeds)."""
        return {key: float(np.mean([r.value(key) for r in self.runs])) for key, *_ in COLUMNS}

    def summary(self) -> dict[str, Any]:
        return {
            "worlds": list(self.first_maps),
            "seeds": len(self.runs) // max(len(self.first_maps), 1),
            "resolution": self.resolution,
            "mapper": self.mapper,
            "t_avg": round(self.t_avg, 4),
            "table": [
                {k: (_rounded(v) if isinstance(v, dict) else v) for k, v in asdict(r).items()} for r in self.table()
            ],
            "overall": _rounded(self.overall()),
            "runs": [r.as_dict() for r in self.runs],
            "wall_time_s": round(self.wall_time_s, 3),
        }


def _rounded(values: dict[str, float]) -> dict[str, float]:
    return {k: round(v, 6) for k, v in values.items()}


def load_worlds(names: Sequence[str]) -> list[World]:
    """Each world once, in the order given; two different worlds may not share a name."""
    worlds: dict[str, World] = {}
    for name in names:
        world = load_world(name)
        other = worlds.get(world.name)
        if other is not None and other.source != world.source:
            raise WorldError(f"{world.source or name}: another world given is also named {world.name!r}")
        worlds.setdefault(world.name, world)
    return list(worlds.values())


def evaluate(
    worlds: Sequence[World],
    cfg: RunConfig,
    noise: SimNoise,
    seeds: int,
    on_run_done: Callable[[RunResult, int], None] | None = None,
    on_step: Callable[[str, int, StepResult], None] | None = None,
) -> Evaluation:
    """Simulate every world with seeds ``0..seeds-1`` and score all the runs as one set."""
    wall0 = time.perf_counter()
    results: list[tuple[RunResult, int]] = []
    for world in worlds:
        for seed in range(seeds):

            def step_hook(step: StepResult, world: str = world.name, seed: int = seed) -> None:
                if on_step is not None:
                    on_step(world, seed, step)

            result = simulate(world, cfg.robot, noise, cfg.slam, seed=seed, on_step=step_hook)
            results.append((result, seed))
            if on_run_done is not None:
                on_run_done(result, seed)
    metrics = score_many([(r.states, r.truth) for r, _ in results])
    runs = [
        RunScore(
            world=r.world,
            seed=seed,
            metrics=m,
            xy_cm=r.final_xy_error_m * 100.0,
            theta_deg=r.final_theta_error_deg,
            steps=r.steps,
            sim_time_s=r.sim_time_s,
            wall_time_s=r.wall_time_s,
            terminated_by=r.terminated_by,
        )
        for (r, seed), m in zip(results, metrics, strict=True)
    ]
    t_avg = float(np.mean([w.grid(cfg.slam.resolution).total_cells for w in worlds])) if worlds else 0.0
    return Evaluation(
        runs=runs,
        first_maps={r.world: r for r, seed in results if seed == 0},
        t_avg=t_avg,
        resolution=cfg.slam.resolution,
        mapper=cfg.slam.mapper,
        wall_time_s=time.perf_counter() - wall0,
    )


def format_table(ev: Evaluation) -> str:
    """The table as text: per world the mean over the seeds and, in brackets, the worst seed."""
    head = f"{'world':<12s} {'cols x rows':>11s} {'N':>5s} {'T':>5s}"
    lines = [head + "".join(f" {heading:^19s}" for _, heading, _, _ in COLUMNS)]
    lines.append("-" * len(lines[0]))

    def cell(mean: str, worst: str) -> str:
        return f" {mean:>9s} {worst:<9s}"

    for row in ev.table():
        vals = "".join(cell(fmt.format(row.mean[key]), f"({fmt.format(row.worst[key])})") for key, _, fmt, _ in COLUMNS)
        size = f"{row.cols} x {row.rows}"
        lines.append(f"{row.world:<12s} {size:>11s} {row.non_vacant:>5d} {row.total_cells:>5d}" + vals)
    overall = ev.overall()
    vals = "".join(cell(fmt.format(overall[key]), "") for key, _, fmt, _ in COLUMNS)
    lines.append(f"{'mean':<12s} {'':>11s} {'':>5s} {'':>5s}" + vals)
    seeds = len(ev.runs) // max(len(ev.first_maps), 1)
    lines.append(
        f"{seeds} seed(s) per world, {ev.mapper} mapper at {ev.resolution} m; mean (worst seed); "
        f"error ratio with T_avg = {ev.t_avg:.2f} over {len(ev.first_maps)} world(s)"
    )
    return "\n".join(line.rstrip() for line in lines)


# -- figures ------------------------------------------------------------------------------------
def _map_image(states: NDArray[np.int8]) -> NDArray[np.uint8]:
    image = np.full(states.shape, 128, dtype=np.uint8)
    image[states == OCCUPIED] = 0
    image[states == FREE] = 255
    return image


def _draw_map(ax: Any, states: NDArray[np.int8], grid: GridSpec, title: str) -> None:
    extent = (grid.origin_x, grid.origin_x + grid.width_m, grid.origin_y, grid.origin_y + grid.height_m)
    ax.imshow(_map_image(states), cmap="gray", vmin=0, vmax=255, extent=extent, interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.tick_params(labelsize=7)


def write_figures(out: Path, ev: Evaluation) -> list[Path]:
    """``maps.png`` (each world's seed-0 map beside its truth) and ``scores.png`` (F1, precision and
    error ratio against the number of non-vacant cells, mean with the seeds' range)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(ev.first_maps)
    fig = Figure(figsize=(7.0, 3.2 * n), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(n, 2, squeeze=False)
    for i, (name, result) in enumerate(ev.first_maps.items()):
        m = result.metrics
        _draw_map(axes[i][0], result.states, result.grid, f"{name}: map, seed 0 (E = {m.cell_errors})")
        if result.trajectory:
            path = np.array(result.trajectory)
            axes[i][0].plot(path[:, 1], path[:, 2], color="tab:blue", linewidth=0.6, alpha=0.7)
        _draw_map(axes[i][1], result.truth, result.grid, f"{name}: ground truth (N = {m.non_vacant})")
    maps_path = out / "maps.png"
    fig.savefig(maps_path, dpi=110)

    rows = sorted(ev.table(), key=lambda r: r.non_vacant)
    fig = Figure(figsize=(6.4, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = np.array([r.non_vacant for r in rows], dtype=float)
    for key, label, marker in (("f1", "F1", "o"), ("precision", "precision", "s"), ("error_ratio", "error ratio", "^")):
        per_world = [[run.value(key) for run in ev.runs if run.world == r.world] for r in rows]
        mean = np.array([np.mean(v) for v in per_world])
        lo = mean - np.array([np.min(v) for v in per_world])
        hi = np.array([np.max(v) for v in per_world]) - mean
        ax.errorbar(x, mean, yerr=[lo, hi], marker=marker, capsize=3, linestyle="-", label=label)
    for r, xi in zip(rows, x, strict=True):
        ax.annotate(r.world, (xi, 0.0), textcoords="offset points", xytext=(0, 4), ha="center", fontsize=7)
    ax.set_xlabel("non-vacant cells N")
    ax.set_ylabel("score")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{ev.mapper} mapper at {ev.resolution} m, mean and range over the seeds", fontsize=9)
    scores_path = out / "scores.png"
    fig.savefig(scores_path, dpi=110)
    return [maps_path, scores_path]


# -- the command ------------------------------------------------------------------------------------
def run_evaluation(args: argparse.Namespace) -> int:
    """``sonarslam evaluate``: the table on stdout (or JSON on the last line), figures and maps with --out."""
    worlds = load_worlds(args.worlds)
    cfg = load_run_config(args.config, {"resolution": args.resolution, "mapper": args.mapper})
    noise = SimNoise.off() if getattr(args, "noise", "default") == "off" else cfg.noise
    out = Path(args.out) if args.out else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(
        total=len(worlds) * args.seeds,
        unit="run",
        desc="evaluate",
        file=sys.stderr,
        disable=args.json or not sys.stderr.isatty(),
        leave=False,
    )

    def on_step(world: str, seed: int, step: StepResult) -> None:
        if step.step % 25 == 0:
            bar.set_postfix_str(f"{world} seed {seed} step {step.step}", refresh=True)

    def on_run_done(result: RunResult, seed: int) -> None:
        if out is not None:
            summary = result.summary(cfg.slam.resolution, seed, cfg.slam.mapper)
            write_run_outputs(out / "runs" / result.world / f"seed{seed}", result, summary)
        bar.update(1)

    try:
        ev = evaluate(worlds, cfg, noise, args.seeds, on_run_done=on_run_done, on_step=on_step)
    finally:
        bar.close()
    summary = ev.summary()
    table = format_table(ev)
    if out is not None:
        figures = write_figures(out, ev)
        atomic_write_bytes(out / "evaluation.json", (json.dumps(summary, indent=2) + "\n").encode())
        atomic_write_bytes(out / "table.txt", (table + "\n").encode())
        summary["files"] = [str(p) for p in figures] + [str(out / "evaluation.json"), str(out / "table.txt")]
    if args.json:
        print(json.dumps(summary, separators=(",", ":")))
    else:
        print(table)
        if out is not None:
            print(f"wrote {out}/maps.png, scores.png, table.txt, evaluation.json and runs/<world>/seed<n>/")
    return 0
