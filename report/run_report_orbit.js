// The run page's orbit view (report/run_report.cc inlines this file): the cameras as frusta,
// prior grey, ground truth blue, refined coloured by its correction; drag to turn, wheel to zoom,
// click a camera to open its panel (the page's #cam-NAME target). Coordinates come in the
// centres' principal frame (x: main direction, z: least), so z is drawn up.
(function () {
  'use strict';
  const data = JSON.parse(document.getElementById('orbit-data').textContent);
  const canvas = document.getElementById('orbit');
  const context = canvas.getContext('2d');
  const view = { yaw: 0.5, pitch: 0.35, zoom: 1.0 };
  const show = { prior: true, truth: true };
  let radius = 1e-9;
  for (const camera of data.cameras) {
    radius = Math.max(radius, Math.hypot(camera.c[0], camera.c[1], camera.c[2]));
  }
  // Frusta three times as deep as the median distance between neighbouring cameras, between a
  // hundredth and a tenth of the spread: a dense video does not draw as one tube.
  const nearest = data.cameras.map((a) => {
    let best = Infinity;
    for (const b of data.cameras) {
      if (a !== b) best = Math.min(best, Math.hypot(a.c[0] - b.c[0], a.c[1] - b.c[1], a.c[2] - b.c[2]));
    }
    return best;
  }).sort((x, y) => x - y);
  const spacing = nearest.length > 1 ? nearest[Math.floor(nearest.length / 2)] : radius;
  const depth = Math.max(0.01 * radius, Math.min(0.1 * radius, 3 * spacing));

  function turn(p) {
    const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw);
    const cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    const x = cy * p[0] + sy * p[1];
    const y = -sy * p[0] + cy * p[1];
    return [x, cp * y - sp * p[2], sp * y + cp * p[2]];
  }
  function toScreen(p) {
    const q = turn(p);
    const scale = (0.45 * Math.min(canvas.width, canvas.height) * view.zoom) / radius;
    return [canvas.width / 2 + scale * q[0], canvas.height / 2 - scale * q[2]];
  }
  function frustum(centre, rotation, half, colour, width) {
    // Camera axes (OpenCV: x right, y down, z forward) as the columns of `rotation` (row-major).
    const corner = (sx, sy) => [0, 1, 2].map(
      (i) => centre[i] + depth * (rotation[3 * i] * sx * half[0] + rotation[3 * i + 1] * sy * half[1] +
        rotation[3 * i + 2]));
    const corners = [corner(-1, -1), corner(1, -1), corner(1, 1), corner(-1, 1)].map(toScreen);
    const apex = toScreen(centre);
    context.strokeStyle = colour;
    context.lineWidth = width;
    context.beginPath();
    for (const c of corners) {
      context.moveTo(apex[0], apex[1]);
      context.lineTo(c[0], c[1]);
    }
    context.moveTo(corners[3][0], corners[3][1]);
    for (const c of corners) context.lineTo(c[0], c[1]);
    context.stroke();
  }
  function selected() {
    return decodeURIComponent(window.location.hash.replace(/^#cam-/, ''));
  }
  function draw() {
    context.clearRect(0, 0, canvas.width, canvas.height);
    const chosen = selected();
    for (const camera of data.cameras) {
      if (show.prior && camera.p) frustum(camera.p, camera.pr, camera.k, '#aaa', 1);
      if (show.truth && camera.g) frustum(camera.g, camera.gr, camera.k, '#36c', 1);
    }
    for (const camera of data.cameras) {
      if (camera.p) {
        const a = toScreen(camera.p), b = toScreen(camera.c);
        context.strokeStyle = camera.colour;
        context.lineWidth = 1;
        context.beginPath();
        context.moveTo(a[0], a[1]);
        context.lineTo(b[0], b[1]);
        context.stroke();
      }
      const mine = camera.n === chosen;
      frustum(camera.c, camera.r, camera.k, mine ? '#000' : camera.colour, mine ? 3 : 1.5);
    }
  }
  // Where camera `name`'s refined centre is drawn, in the window's coordinates (for scripts and
  // the browser test: the page has nothing else to click on in the canvas).
  function screenPosition(name) {
    const camera = data.cameras.find((c) => c.n === name);
    if (!camera) return null;
    const s = toScreen(camera.c);
    const box = canvas.getBoundingClientRect();
    return [box.left + (s[0] * box.width) / canvas.width, box.top + (s[1] * box.height) / canvas.height];
  }
  function pick(event) {
    const box = canvas.getBoundingClientRect();
    const x = ((event.clientX - box.left) * canvas.width) / box.width;
    const y = ((event.clientY - box.top) * canvas.height) / box.height;
    let best = null, best_distance = 10;
    for (const camera of data.cameras) {
      const s = toScreen(camera.c);
      const d = Math.hypot(s[0] - x, s[1] - y);
      if (d < best_distance) {
        best = camera;
        best_distance = d;
      }
    }
    if (best) window.location.hash = 'cam-' + best.n;
  }

  let drag = null;
  canvas.addEventListener('mousedown', (event) => {
    drag = { x: event.clientX, y: event.clientY, moved: false };
  });
  window.addEventListener('mousemove', (event) => {
    if (!drag) return;
    const dx = event.clientX - drag.x, dy = event.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    if (!drag.moved) return;
    view.yaw += dx * 0.01;
    view.pitch = Math.max(-1.5, Math.min(1.5, view.pitch + dy * 0.01));
    drag.x = event.clientX;
    drag.y = event.clientY;
    draw();
  });
  window.addEventListener('mouseup', (event) => {
    if (drag && !drag.moved && event.target === canvas) pick(event);
    drag = null;
  });
  canvas.addEventListener('wheel', (event) => {
    event.preventDefault();
    view.zoom = Math.max(0.2, Math.min(50, view.zoom * Math.exp(-event.deltaY * 0.001)));
    draw();
  }, { passive: false });
  for (const name of ['prior', 'truth']) {
    const box = document.getElementById('orbit-' + name);
    if (!box) continue;
    box.addEventListener('change', () => {
      show[name] = box.checked;
      draw();
    });
  }
  window.addEventListener('hashchange', draw);
  window.raytimeOrbit = { screenPosition: screenPosition, view: view, draw: draw };
  draw();
})();
