// The map view: draws the cell layers scaled to the canvas with the robot, trail, beams and target;
// zoom (wheel, pinch, buttons, + / -) and pan (drag, arrow keys); the scale bar in metres.

const BACKGROUND = '#2b3038';
const MIN_CELL_PX = 0.5;
const MAX_CELL_PX = 240;
const PAN_STEP_PX = 48;
const ZOOM_STEP = 1.25;
const NICE_LENGTHS_M = [0.01, 0.02, 0.05, 0.1, 0.2, 0.25, 0.5, 1, 2, 5, 10, 20, 50, 100];

function lengthLabel(m) {
  return m < 1 ? `${Math.round(m * 100)} cm` : `${m} m`;
}

export class MapView {
  /**
   * @param {HTMLCanvasElement} canvas the visible canvas (focusable)
   * @param {object} parts { mapLayer, truthLayer, scaleBar: {bar, label} }
   */
  constructor(canvas, { mapLayer, truthLayer, scaleBar }) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.mapLayer = mapLayer;
    this.truthLayer = truthLayer;
    this.scaleBar = scaleBar;
    this.grid = null; // {rows, cols, resolution, origin: [x, y]}
    this.robot = null; // {radius_m, beam_width_deg, max_range_m, sonars: [...]}
    this.pose = null; // {x, y, theta}
    this.trail = [];
    this.sweep = null;
    this.target = null;
    this.layers = { robot: true, trail: true, beams: true, target: true, truth: false };
    this.scale = 40; // CSS pixels per metre
    this.ox = 0; // CSS pixels from the canvas's left edge to the grid's left edge
    this.oy = 0; // ... and from its top edge to the grid's top edge
    this.userMoved = false; // once the user zoomed or panned, new data does not refit the view
    this.cssW = 0;
    this.cssH = 0;
    this.dpr = 1;
    this._frame = 0;
    this._pointers = new Map();
    this._bindInput();
    this._resizeObserver = new ResizeObserver(() => this._resize());
    this._resizeObserver.observe(canvas);
    this._resize();
  }

  // -- data ----------------------------------------------------------------------------------------
  setGrid(grid) {
    const old = this.grid;
    this.grid = grid;
    const same =
      old && old.rows === grid.rows && old.cols === grid.cols && old.resolution === grid.resolution;
    if (!same || !this.userMoved) this.fit();
    this.requestDraw();
  }

  clear() {
    this.grid = null;
    this.robot = null;
    this.pose = null;
    this.trail = [];
    this.sweep = null;
    this.target = null;
    this.userMoved = false;
    this.requestDraw();
  }

  setLayer(name, on) {
    this.layers[name] = on;
    this.requestDraw();
  }

  // -- geometry ------------------------------------------------------------------------------------
  get cellPx() {
    return this.grid ? this.grid.resolution * this.scale : 0;
  }

  /** Canvas CSS pixel of a map-frame point [m]. */
  toCanvas(x, y) {
    const g = this.grid;
    const top = g.origin[1] + g.rows * g.resolution;
    return [this.ox + (x - g.origin[0]) * this.scale, this.oy + (top - y) * this.scale];
  }

  /** Viewport (client) coordinates of a cell's centre, or null without a grid. */
  cellToClient(row, col) {
    if (!this.grid) return null;
    const rect = this.canvas.getBoundingClientRect();
    const px = this.cellPx;
    return {
      x: rect.left + this.canvas.clientLeft + this.ox + (col + 0.5) * px,
      y: rect.top + this.canvas.clientTop + this.oy + (row + 0.5) * px,
    };
  }

  /** Viewport (client) coordinates of a map-frame point [m], or null without a grid. */
  worldToClient(x, y) {
    if (!this.grid) return null;
    const rect = this.canvas.getBoundingClientRect();
    const [cx, cy] = this.toCanvas(x, y);
    return { x: rect.left + this.canvas.clientLeft + cx, y: rect.top + this.canvas.clientTop + cy };
  }

  fit() {
    this.userMoved = false;
    if (!this.grid || this.cssW === 0 || this.cssH === 0) return;
    const g = this.grid;
    const margin = 8;
    const w = g.cols * g.resolution;
    const h = g.rows * g.resolution;
    this.scale = Math.max(1e-6, Math.min((this.cssW - 2 * margin) / w, (this.cssH - 2 * margin) / h));
    this.ox = (this.cssW - w * this.scale) / 2;
    this.oy = (this.cssH - h * this.scale) / 2;
    this.requestDraw();
  }

  /** Zoom by `factor` keeping the point (cx, cy) in canvas CSS pixels where it is. */
  zoomAt(factor, cx = this.cssW / 2, cy = this.cssH / 2) {
    if (!this.grid) return;
    const res = this.grid.resolution;
    const next = Math.min(MAX_CELL_PX / res, Math.max(MIN_CELL_PX / res, this.scale * factor));
    const k = next / this.scale;
    this.ox = cx - (cx - this.ox) * k;
    this.oy = cy - (cy - this.oy) * k;
    this.scale = next;
    this.userMoved = true;
    this.requestDraw();
  }

  panBy(dx, dy) {
    this.ox += dx;
    this.oy += dy;
    this.userMoved = true;
    this.requestDraw();
  }

  _resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = this.canvas.clientWidth;
    const h = this.canvas.clientHeight;
    if (w === this.cssW && h === this.cssH && dpr === this.dpr) return;
    // Keep the centre of the view where it was.
    this.ox += (w - this.cssW) / 2;
    this.oy += (h - this.cssH) / 2;
    this.cssW = w;
    this.cssH = h;
    this.dpr = dpr;
    this.canvas.width = Math.max(1, Math.round(w * dpr));
    this.canvas.height = Math.max(1, Math.round(h * dpr));
    if (!this.userMoved) this.fit();
    this.draw();
  }

  // -- input ---------------------------------------------------------------------------------------
  _bindInput() {
    const c = this.canvas;
    c.addEventListener(
      'wheel',
      (e) => {
        if (!this.grid) return;
        e.preventDefault();
        const unit = e.deltaMode === 1 ? 16 : e.deltaMode === 2 ? this.cssH : 1;
        const rect = c.getBoundingClientRect();
        this.zoomAt(Math.exp(-e.deltaY * unit * 0.0015), e.clientX - rect.left, e.clientY - rect.top);
      },
      { passive: false },
    );
    c.addEventListener('pointerdown', (e) => {
      if (e.pointerType === 'mouse' && e.button !== 0) return;
      c.setPointerCapture(e.pointerId);
      this._pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      c.classList.add('dragging');
    });
    c.addEventListener('pointermove', (e) => {
      const prev = this._pointers.get(e.pointerId);
      if (!prev) return;
      if (this._pointers.size === 1) {
        this.panBy(e.clientX - prev.x, e.clientY - prev.y);
      } else if (this._pointers.size === 2) {
        // Pinch: zoom by the change in finger distance about their midpoint.
        const [a, b] = [...this._pointers.entries()].map(([id, p]) => (id === e.pointerId ? { x: e.clientX, y: e.clientY } : p));
        const [pa, pb] = [...this._pointers.values()];
        const before = Math.hypot(pa.x - pb.x, pa.y - pb.y);
        const after = Math.hypot(a.x - b.x, a.y - b.y);
        const rect = c.getBoundingClientRect();
        if (before > 0) this.zoomAt(after / before, (a.x + b.x) / 2 - rect.left, (a.y + b.y) / 2 - rect.top);
      }
      this._pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    });
    const release = (e) => {
      this._pointers.delete(e.pointerId);
      if (this._pointers.size === 0) c.classList.remove('dragging');
    };
    c.addEventListener('pointerup', release);
    c.addEventListener('pointercancel', release);
    c.addEventListener('keydown', (e) => {
      if (e.altKey || e.ctrlKey || e.metaKey) return;
      const moves = {
        ArrowLeft: [PAN_STEP_PX, 0],
        ArrowRight: [-PAN_STEP_PX, 0],
        ArrowUp: [0, PAN_STEP_PX],
        ArrowDown: [0, -PAN_STEP_PX],
      };
      if (e.key in moves) {
        this.panBy(...moves[e.key]);
      } else if (e.key === '+' || e.key === '=') {
        this.zoomAt(ZOOM_STEP);
      } else if (e.key === '-' || e.key === '_') {
        this.zoomAt(1 / ZOOM_STEP);
      } else if (e.key === '0' || e.key === 'f') {
        this.fit();
      } else {
        return;
      }
      e.preventDefault();
    });
  }

  // -- drawing -------------------------------------------------------------------------------------
  requestDraw() {
    if (this._frame) return;
    this._frame = requestAnimationFrame(() => {
      this._frame = 0;
      this.draw();
    });
  }

  draw() {
    const ctx = this.ctx;
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    ctx.fillStyle = BACKGROUND;
    ctx.fillRect(0, 0, this.cssW, this.cssH);
    this._updateScaleBar();
    if (!this.grid || !this.mapLayer.loaded) return;
    const g = this.grid;
    const w = g.cols * this.cellPx;
    const h = g.rows * this.cellPx;
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.mapLayer.canvas, this.ox, this.oy, w, h);
    if (this.layers.truth && this.truthLayer.loaded) ctx.drawImage(this.truthLayer.canvas, this.ox, this.oy, w, h);
    this._drawCellLines(w, h);
    if (this.layers.beams) this._drawBeams();
    if (this.layers.trail) this._drawTrail();
    if (this.layers.robot) this._drawRobot();
    if (this.layers.target) this._drawTarget(); // on top: the target is often the cell just reached
  }

  _drawCellLines(w, h) {
    const ctx = this.ctx;
    const px = this.cellPx;
    ctx.lineWidth = 1;
    ctx.strokeStyle = 'rgba(120, 120, 120, 0.9)';
    ctx.strokeRect(this.ox - 0.5, this.oy - 0.5, w + 1, h + 1);
    if (px < 14) return; // lines would swamp small cells
    ctx.strokeStyle = 'rgba(90, 90, 90, 0.18)';
    ctx.beginPath();
    for (let c = 1; c < this.grid.cols; c += 1) {
      const x = Math.round(this.ox + c * px) + 0.5;
      ctx.moveTo(x, this.oy);
      ctx.lineTo(x, this.oy + h);
    }
    for (let r = 1; r < this.grid.rows; r += 1) {
      const y = Math.round(this.oy + r * px) + 0.5;
      ctx.moveTo(this.ox, y);
      ctx.lineTo(this.ox + w, y);
    }
    ctx.stroke();
  }

  _drawBeams() {
    const { robot, pose, sweep } = this;
    if (!robot || !pose || !Array.isArray(sweep) || !Array.isArray(robot.sonars)) return;
    const ctx = this.ctx;
    const half = ((robot.beam_width_deg ?? 30) * Math.PI) / 360;
    const maxRange = robot.max_range_m ?? Infinity;
    const cos = Math.cos(pose.theta);
    const sin = Math.sin(pose.theta);
    robot.sonars.forEach((sonar, i) => {
      const range = sweep[i];
      if (typeof range !== 'number' || !(range > 0)) return;
      const ox = sonar.offset_x_m ?? 0;
      const oy = sonar.offset_y_m ?? 0;
      const [sx, sy] = this.toCanvas(pose.x + cos * ox - sin * oy, pose.y + sin * ox + cos * oy);
      const dir = pose.theta + ((sonar.bearing_deg ?? 0) * Math.PI) / 180;
      const r = range * this.scale;
      const echo = range < maxRange - 1e-6;
      // Screen y points down, so a counter-clockwise map angle a is the screen angle -a.
      ctx.beginPath();
      ctx.moveTo(sx, sy);
      ctx.arc(sx, sy, r, -dir - half, -dir + half);
      ctx.closePath();
      ctx.fillStyle = echo ? 'rgba(64, 192, 87, 0.16)' : 'rgba(64, 192, 87, 0.06)';
      ctx.fill();
      ctx.setLineDash(echo ? [] : [4, 4]);
      ctx.lineWidth = 1;
      ctx.strokeStyle = echo ? 'rgba(47, 158, 68, 0.7)' : 'rgba(47, 158, 68, 0.35)';
      ctx.stroke();
      ctx.setLineDash([]);
      if (echo) {
        ctx.beginPath();
        ctx.arc(sx, sy, r, -dir - half, -dir + half);
        ctx.lineWidth = 3;
        ctx.strokeStyle = 'rgba(43, 138, 62, 0.95)';
        ctx.stroke();
      }
    });
  }

  _drawTrail() {
    if (this.trail.length < 2) return;
    const ctx = this.ctx;
    ctx.beginPath();
    this.trail.forEach(([x, y], i) => {
      const [cx, cy] = this.toCanvas(x, y);
      if (i === 0) ctx.moveTo(cx, cy);
      else ctx.lineTo(cx, cy);
    });
    ctx.lineWidth = 2;
    ctx.lineJoin = 'round';
    ctx.strokeStyle = 'rgba(28, 126, 214, 0.85)';
    ctx.stroke();
  }

  _drawTarget() {
    if (!Array.isArray(this.target) || this.target.length < 2) return;
    const ctx = this.ctx;
    const [tx, ty] = this.toCanvas(this.target[0], this.target[1]);
    if (this.pose) {
      const [px, py] = this.toCanvas(this.pose.x, this.pose.y);
      ctx.beginPath();
      ctx.moveTo(px, py);
      ctx.lineTo(tx, ty);
      ctx.setLineDash([5, 4]);
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = 'rgba(194, 37, 92, 0.9)';
      ctx.stroke();
      ctx.setLineDash([]);
    }
    const s = Math.max(7, Math.min(16, this.cellPx * 0.45));
    ctx.beginPath();
    ctx.moveTo(tx, ty - s);
    ctx.lineTo(tx + s, ty);
    ctx.lineTo(tx, ty + s);
    ctx.lineTo(tx - s, ty);
    ctx.closePath();
    ctx.lineWidth = 2;
    ctx.strokeStyle = '#c2255c';
    ctx.stroke();
  }

  _drawRobot() {
    if (!this.pose) return;
    const ctx = this.ctx;
    const [cx, cy] = this.toCanvas(this.pose.x, this.pose.y);
    const radius = Math.max(4, ((this.robot && this.robot.radius_m) || 0.06) * this.scale);
    ctx.beginPath();
    ctx.arc(cx, cy, radius, 0, 2 * Math.PI);
    ctx.fillStyle = 'rgba(232, 89, 12, 0.9)';
    ctx.fill();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = '#fff';
    ctx.stroke();
    const len = radius * 1.7;
    ctx.beginPath();
    ctx.moveTo(cx, cy);
    ctx.lineTo(cx + Math.cos(this.pose.theta) * len, cy - Math.sin(this.pose.theta) * len);
    ctx.lineWidth = 2.5;
    ctx.strokeStyle = '#7a2e00';
    ctx.stroke();
  }

  _updateScaleBar() {
    const { bar, label } = this.scaleBar;
    if (!this.grid) {
      bar.style.width = '0px';
      label.textContent = '';
      return;
    }
    // The longest "nice" length that stays under a third of the view (and at least 40 px).
    const limit = Math.max(40, Math.min(160, this.cssW / 3));
    let best = NICE_LENGTHS_M[0];
    for (const m of NICE_LENGTHS_M) if (m * this.scale <= limit) best = m;
    bar.style.width = `${Math.round(best * this.scale)}px`;
    label.textContent = lengthLabel(best);
  }
}
