"""The sonarslam command line: truth, score, run, evaluate, replay, serve and check-hardware."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, NoReturn

from robot.errors import SonarSlamError

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit with status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0 or value >= 2**63:
        raise argparse.ArgumentTypeError(f"must be between 0 and 2^63-1, got {text}")
    return value


def _count(text: str) -> int:
    value = _seed(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return value


def _print_json(obj: Any) -> None:
    print(json.dumps(obj, separators=(",", ":")))


# -- commands ---------------------------------------------------------------------------------------
def cmd_worlds(args: argparse.Namespace) -> int:
    from robot.world import builtin_worlds, load_world

    rows = []
    for name in builtin_worlds():
        w = load_world(name)
        min_x, min_y, max_x, max_y = w.bounds
        rows.append(
            {
                "name": name,
                "width_m": round(max_x - min_x, 3),
                "height_m": round(max_y - min_y, 3),
                "obstacles": len(w.obstacles),
                "description": w.description,
            }
        )
    if args.json:
        _print_json(rows)
    else:
        for r in rows:
            print(
                f"{r['name']:10s} {r['width_m']:5.2f} x {r['height_m']:5.2f} m  "
                f"{r['obstacles']:2d} obstacles  {r['description']}"
            )
    return 0


def cmd_truth(args: argparse.Namespace) -> int:
    from robot.mapio import write_truth_files
    from robot.truth import truth_grid
    from robot.world import load_world

    world = load_world(args.world)
    grid, truth = truth_grid(world, args.resolution)
    out = Path(args.out)
    paths = write_truth_files(out, truth, grid)
    summary = {
        "world": world.name,
        "resolution": args.resolution,
        "rows": grid.rows,
        "cols": grid.cols,
        "white": int((truth == 0).sum()),
        "black": int((truth == 1).sum()),
        "grey": int((truth == -1).sum()),
        "files": {k: str(v) for k, v in paths.items()},
    }
    if args.json:
        _print_json(summary)
    else:
        print(
            f"{world.name}: {grid.cols} x {grid.rows} cells at {args.resolution} m; "
            f"white {summary['white']}, black {summary['black']}, grey {summary['grey']}"
        )
        for p in paths.values():
            print(f"wrote {p}")
    return 0


def cmd_score(args: argparse.Namespace) -> int:
    from robot.mapio import read_csv
    from robot.metrics import score
    from robot.truth import truth_grid
    from robot.world import load_world

    world = load_world(args.world)
    grid, truth = truth_grid(world, args.resolution)
    estimate = read_csv(args.map, expected_shape=grid.shape)
    m = score(estimate, truth)
    if args.json:
        _print_json(
            {
                "world": world.name,
                "resolution": args.resolution,
                "rows": grid.rows,
                "cols": grid.cols,
                "metrics": m.as_dict(),
            }
        )
    else:
        print(
            f"{world.name} at {args.resolution} m ({grid.cols} x {grid.rows}): cell errors {m.cell_errors}, "
            f"non-vacant {m.non_vacant}, error ratio {m.error_ratio:.4f}, precision {m.precision:.4f}, "
            f"recall {m.recall:.4f}, F1 {m.f1:.4f}"
        )
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from robot.runner import simulate, write_run_outputs
    from robot.settings import load_run_config
    from robot.world import load_world

    world = load_world(args.world)
    cfg = load_run_config(args.config, {"resolution": args.resolution, "mapper": args.mapper})
    noise = cfg.noise
    if args.noise == "off":
        from robot.config import SimNoise

        noise = SimNoise.off()
    progress = None
    if not args.json and not args.quiet and sys.stderr.isatty():
        progress = _step_printer()
    log_path = None
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        log_path = Path(args.out) / "sensors.log"
    result = simulate(world, cfg.robot, noise, cfg.slam, seed=args.seed, on_step=progress, log_path=log_path)
    if progress is not None:
        sys.stderr.write("\n")
    summary = result.summary(cfg.slam.resolution, args.seed, cfg.slam.mapper)
    if args.out:
        write_run_outputs(Path(args.out), result, summary)
    if args.json:
        _print_json(summary)
    else:
        m = result.metrics
        print(
            f"{world.name}: {result.steps} steps, {result.sim_time_s:.0f} s simulated in {result.wall_time_s:.2f} s, "
            f"ended by {result.terminated_by}"
        )
        print(
            f"cell errors {m.cell_errors}/{m.non_vacant} non-vacant, error ratio {m.error_ratio:.4f}, "
            f"precision {m.precision:.4f}, recall {m.recall:.4f}, F1 {m.f1:.4f}"
        )
        print(f"final pose error {result.final_xy_error_m * 100:.1f} cm, {result.final_theta_error_deg:.2f} deg")
        if args.out:
            print(
                f"wrote {args.out}/: map.csv, map.png, map.pgm, map.yaml, truth.csv, trajectory.csv, "
                "sensors.log, run.json"
            )
    return 0


def _step_printer() -> Any:
    def show(step: Any) -> None:
        if step.step % 10 == 0 or step.done:
            sys.stderr.write(f"\rstep {step.step:5d}  t={step.t_s:7.0f} s  frontier {step.frontier_cells:4d}   ")
            sys.stderr.flush()

    return show


def cmd_evaluate(args: argparse.Namespace) -> int:
    from robot.evaluate import run_evaluation

    return run_evaluation(args)


def cmd_replay(args: argparse.Namespace) -> int:
    from robot.replay import run_replay

    return run_replay(args)


def cmd_serve(args: argparse.Namespace) -> int:
    from server.main import serve

    return serve(args)


def cmd_check_hardware(args: argparse.Namespace) -> int:
    from robot.pi.check import check_hardware

    return check_hardware(args.config, duration_s=args.duration)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="sonarslam", description="Sonar occupancy-grid SLAM: simulate, evaluate, replay and serve.")
    from robot import __version__

    parser.add_argument("--version", action="version", version=f"sonarslam {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("worlds", help="list the built-in worlds")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_worlds)

    p = sub.add_parser("truth", help="write a world's ground-truth map (truth.csv, truth.png)")
    p.add_argument("world", help="built-in world name or world TOML file")
    p.add_argument("--resolution", type=_positive_float, default=0.2, help="cell side in metres (default 0.2)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_truth)

    p = sub.add_parser("score", help="score a map CSV against a world's ground truth")
    p.add_argument("world")
    p.add_argument("map", help="map.csv to score")
    p.add_argument("--resolution", type=_positive_float, default=0.2)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_score)

    p = sub.add_parser("run", help="explore a simulated world to the end and score the map")
    p.add_argument("--world", required=True, help="built-in world name or world TOML file")
    p.add_argument("--seed", type=_seed, default=0)
    p.add_argument(
        "--resolution", type=_positive_float, default=None, help="map cell side in metres (default from config)"
    )
    p.add_argument("--mapper", choices=("logodds", "paper"), default=None)
    p.add_argument("--config", default=None, help="TOML file overriding [slam], [sim_noise] or robot settings")
    p.add_argument("--noise", choices=("default", "off"), default="default", help="simulator errors (default: on)")
    p.add_argument(
        "--out", default=None, help="directory for map.csv/png/pgm/yaml, truth.csv, trajectory.csv, run.json"
    )
    p.add_argument("--json", action="store_true", help="print the run summary as JSON on the last line")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("evaluate", help="Table-I-style scores over several worlds and seeds")
    p.add_argument("worlds", nargs="+", metavar="WORLD")
    p.add_argument("--seeds", type=_count, default=3, help="seeds per world (default 3)")
    p.add_argument("--resolution", type=_positive_float, default=None)
    p.add_argument("--mapper", choices=("logodds", "paper"), default=None)
    p.add_argument("--config", default=None)
    p.add_argument("--noise", choices=("default", "off"), default="default", help="simulator errors (default: on)")
    p.add_argument("--out", default=None, help="directory for figures and per-run maps")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("replay", help="map a recorded sensor log")
    p.add_argument("log", help="log directory (measurement.txt + poses.txt) or a sensors.log file")
    p.add_argument("--config", default=None)
    p.add_argument("--resolution", type=_positive_float, default=None)
    p.add_argument("--out", default=None)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("serve", help="run the web service")
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8000)")
    p.add_argument("--hardware", choices=("sim", "pi"), default=None)
    p.add_argument("--data-dir", default=None, help="where runs are stored")
    p.add_argument("--token", default=None, help="bearer token for control endpoints")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("check-hardware", help="print live readings of the Pi's sensors for bring-up")
    p.add_argument("--config", default="config/robot-pi.toml")
    p.add_argument("--duration", type=_positive_float, default=10.0, help="seconds to watch the encoders")
    p.set_defaults(func=cmd_check_hardware)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except SonarSlamError as exc:
        print(f"sonarslam: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("sonarslam: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
