// A point cloud drawn with WebGL buffers: the Result view's and the live 3-D view's 3-D picture.
// The server sends the points and their colours (the 2-D map's colour map and range, so both views
// agree); this module only uploads them and draws them from an orbiting camera (drag: turn,
// wheel: zoom, double-click: the whole cloud again). The camera is fitted to the cloud's bounding
// sphere, so nothing is cropped whatever the window's shape.

const VERTEX = `
attribute vec3 position;
attribute vec4 colour;
uniform mat4 transform;
uniform float pointSize;
varying vec4 shade;
void main() {
  gl_Position = transform * vec4(position, 1.0);
  gl_PointSize = pointSize;
  shade = colour;
}`;
const FRAGMENT = `
precision mediump float;
varying vec4 shade;
void main() { gl_FragColor = shade; }`;
const FOV = Math.PI / 5;
const BACKGROUND = [1, 1, 1, 1];

// Fetch a cloud (/api/results/NAME/cloud.bin or the live one): positions, colours and what the headers say.
export async function fetchCloud(url) {
  const reply = await fetch(url);
  if (!reply.ok) throw new Error(`${url}: ${reply.status}`);
  const bytes = await reply.arrayBuffer();
  const count = Number(reply.headers.get("X-Points"));
  const [low, high] = (reply.headers.get("X-Range") || "0,1").split(",").map(Number);
  return {
    positions: new Float32Array(bytes, 0, count * 3),
    colours: new Uint8Array(bytes, count * 12, count * 4),
    count, low, high, step: Number(reply.headers.get("X-Step") || 1),
    unit: reply.headers.get("X-Unit") || "", axisUnit: reply.headers.get("X-Axis-Unit") || "",
  };
}

export class CloudView {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext("webgl", { antialias: false, preserveDrawingBuffer: true });
    this.gl = gl;
    if (!gl) return;
    const program = gl.createProgram();
    for (const [kind, source] of [[gl.VERTEX_SHADER, VERTEX], [gl.FRAGMENT_SHADER, FRAGMENT]]) {
      const shader = gl.createShader(kind);
      gl.shaderSource(shader, source);
      gl.compileShader(shader);
      gl.attachShader(program, shader);
    }
    gl.linkProgram(program);
    gl.useProgram(program);
    this.program = program;
    this.positionBuffer = gl.createBuffer();
    this.colourBuffer = gl.createBuffer();
    this.count = 0;
    this.centre = [0, 0, 0];
    this.radius = 1;
    this.resetCamera();
    this.bindMouse();
  }

  get ready() { return Boolean(this.gl); }

  // Upload a cloud (Float32Array xyz, Uint8Array rgba); keepCamera leaves the operator's view as it is.
  setCloud(positions, colours, { keepCamera = false } = {}) {
    const gl = this.gl;
    if (!gl) return;
    this.count = positions.length / 3;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.positionBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, positions, gl.DYNAMIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.colourBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, colours, gl.DYNAMIC_DRAW);
    if (!keepCamera || !this.fitted) { this.fit(positions); this.resetCamera(); }
    this.draw();
  }

  // The bounding sphere of the cloud: what the camera keeps in view.
  fit(positions) {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < positions.length; i += 3) {
      for (let k = 0; k < 3; k++) {
        const v = positions[i + k];
        if (v < lo[k]) lo[k] = v;
        if (v > hi[k]) hi[k] = v;
      }
    }
    if (!(lo[0] <= hi[0])) return;
    this.centre = lo.map((v, k) => (v + hi[k]) / 2);
    this.radius = Math.max(1e-6, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
    this.fitted = true;
  }

  resetCamera() { this.azimuth = -0.5; this.elevation = 0.9; this.zoom = 1; }

  // Draw now; returns once the GPU has drawn (a one-pixel read waits for it), so callers can time it.
  draw() {
    const gl = this.gl;
    if (!gl) return;
    const width = Math.max(1, Math.round(this.canvas.clientWidth * devicePixelRatio));
    const height = Math.max(1, Math.round(this.canvas.clientHeight * devicePixelRatio));
    if (this.canvas.width !== width || this.canvas.height !== height) { this.canvas.width = width; this.canvas.height = height; }
    gl.viewport(0, 0, width, height);
    gl.clearColor(...BACKGROUND);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    if (!this.count) return;
    const aspect = width / height;
    // far enough that the bounding sphere fits the narrower of the two fields of view
    const half = Math.min(FOV / 2, Math.atan(Math.tan(FOV / 2) * aspect));
    const distance = this.radius / Math.sin(half) * 1.05 / this.zoom;
    const eye = [
      this.centre[0] + distance * Math.cos(this.elevation) * Math.cos(this.azimuth),
      this.centre[1] + distance * Math.cos(this.elevation) * Math.sin(this.azimuth),
      this.centre[2] + distance * Math.sin(this.elevation),
    ];
    const near = Math.max(distance - this.radius * 1.5, distance * 1e-3), far = distance + this.radius * 1.5;
    // camera rows grow downwards: mirror y so the cloud is seen as the 2-D map shows it
    const transform = multiply(multiply(perspective(FOV, aspect, near, far), lookAt(eye, this.centre, [0, 0, 1])),
      [1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0, 2 * this.centre[1], 0, 1]);
    const program = this.program;
    gl.uniformMatrix4fv(gl.getUniformLocation(program, "transform"), false, new Float32Array(transform));
    gl.uniform1f(gl.getUniformLocation(program, "pointSize"), Math.max(1.5, 2 * devicePixelRatio));
    const position = gl.getAttribLocation(program, "position"), colour = gl.getAttribLocation(program, "colour");
    gl.bindBuffer(gl.ARRAY_BUFFER, this.positionBuffer);
    gl.enableVertexAttribArray(position);
    gl.vertexAttribPointer(position, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.colourBuffer);
    gl.enableVertexAttribArray(colour);
    gl.vertexAttribPointer(colour, 4, gl.UNSIGNED_BYTE, true, 0, 0);
    gl.drawArrays(gl.POINTS, 0, this.count);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  }

  bindMouse() {
    let last = null;
    const canvas = this.canvas;
    canvas.addEventListener("pointerdown", (e) => { last = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
    canvas.addEventListener("pointerup", () => { last = null; });
    canvas.addEventListener("pointermove", (e) => {
      if (!last) return;
      this.azimuth -= (e.clientX - last[0]) * 0.01;
      this.elevation = Math.max(-1.5, Math.min(1.5, this.elevation + (e.clientY - last[1]) * 0.01));
      last = [e.clientX, e.clientY];
      requestAnimationFrame(() => this.draw());
    });
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.zoom = Math.max(0.2, Math.min(20, this.zoom * Math.exp(-e.deltaY * 0.001)));
      requestAnimationFrame(() => this.draw());
    }, { passive: false });
    canvas.addEventListener("dblclick", () => { this.resetCamera(); this.draw(); });
  }
}

// Column-major 4x4 matrices, as WebGL takes them.
function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) out[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
  return out;
}

function perspective(fov, aspect, near, far) {
  const f = 1 / Math.tan(fov / 2), d = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * d, -1, 0, 0, 2 * far * near * d, 0];
}

function lookAt(eye, target, up) {
  const z = normalise(eye.map((v, i) => v - target[i]));
  const x = normalise(cross(up, z));
  const y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalise = (v) => { const n = Math.hypot(...v) || 1; return v.map((x) => x / n); };
