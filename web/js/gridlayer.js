// A grid of cell codes kept as an offscreen canvas at one pixel per cell, patched cell by cell.

export const FREE = 0;
export const OCCUPIED = 1;
export const UNKNOWN = 2;

/** Map colours: the paper's black / white / grey (grey 128 as in map.png). */
export const MAP_PALETTE = {
  [FREE]: [255, 255, 255, 255],
  [OCCUPIED]: [0, 0, 0, 255],
  [UNKNOWN]: [128, 128, 128, 255],
};

/** Truth overlay: obstacles in translucent red, inaccessible space in translucent blue, free clear. */
export const TRUTH_PALETTE = {
  [FREE]: [0, 0, 0, 0],
  [OCCUPIED]: [224, 49, 49, 150],
  [UNKNOWN]: [51, 102, 204, 80],
};

/** base64 (as in a snapshot's `cells` and `truth`) to bytes. */
export function decodeBase64(text) {
  const bin = atob(text);
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i += 1) out[i] = bin.charCodeAt(i);
  return out;
}

export class CellLayer {
  constructor(palette) {
    this.palette = palette;
    this.canvas = document.createElement('canvas');
    this.canvas.width = 1;
    this.canvas.height = 1;
    this.ctx = this.canvas.getContext('2d');
    this.rows = 0;
    this.cols = 0;
    this.codes = new Uint8Array(0);
    this.image = null;
    this.loaded = false;
  }

  _colour(code) {
    return this.palette[code] || this.palette[UNKNOWN];
  }

  /** Replace the whole layer (a snapshot). `bytes` may be shorter than rows*cols: the rest is unknown. */
  reset(rows, cols, bytes) {
    this.rows = rows;
    this.cols = cols;
    this.canvas.width = Math.max(1, cols);
    this.canvas.height = Math.max(1, rows);
    this.codes = new Uint8Array(rows * cols).fill(UNKNOWN);
    if (bytes) this.codes.set(bytes.subarray(0, rows * cols));
    this.image = this.ctx.createImageData(Math.max(1, cols), Math.max(1, rows));
    const px = this.image.data;
    for (let i = 0; i < this.codes.length; i += 1) px.set(this._colour(this.codes[i]), i * 4);
    this.ctx.putImageData(this.image, 0, 0);
    this.loaded = bytes !== null && bytes !== undefined;
  }

  clear() {
    this.reset(0, 0, null);
    this.loaded = false;
  }

  /**
   * Apply `[row, col, code]` changes in order. Only the pixels of changed cells are rewritten, and
   * only the bounding box of the changes is uploaded to the canvas. Answers how many cells changed.
   */
  patch(changes) {
    if (!this.image || !changes || changes.length === 0) return 0;
    const px = this.image.data;
    let r0 = Infinity;
    let c0 = Infinity;
    let r1 = -1;
    let c1 = -1;
    let n = 0;
    for (const change of changes) {
      const [row, col, code] = change;
      if (!(row >= 0 && row < this.rows && col >= 0 && col < this.cols)) continue;
      const i = row * this.cols + col;
      this.codes[i] = code;
      px.set(this._colour(code), i * 4);
      if (row < r0) r0 = row;
      if (row > r1) r1 = row;
      if (col < c0) c0 = col;
      if (col > c1) c1 = col;
      n += 1;
    }
    if (n > 0) this.ctx.putImageData(this.image, 0, 0, c0, r0, c1 - c0 + 1, r1 - r0 + 1);
    return n;
  }

  code(row, col) {
    if (!(row >= 0 && row < this.rows && col >= 0 && col < this.cols)) return null;
    return this.codes[row * this.cols + col];
  }

  /** Rows of codes, for the test hook and debugging. */
  toRows() {
    const out = [];
    for (let r = 0; r < this.rows; r += 1) out.push(Array.from(this.codes.subarray(r * this.cols, (r + 1) * this.cols)));
    return out;
  }
}
