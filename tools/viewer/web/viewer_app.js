// The page of `cvd view`: the fused point cloud and the camera path of a cvd run in an orbitable
// 3-D view, a frame slider showing input | depth side by side, and the run's key figures.
// Bundled with three.js by esbuild at build time and inlined into viewer.html, so the page needs
// no network. Its data is the JSON in <script id="cvd-data"> that tools/viewer/viewer_page.cpp
// writes (see there for the fields).
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

function decodeBase64(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
  return bytes;
}

// Camera-to-world (row-major 3x4) -> a THREE.Matrix4.
function poseMatrix(c2w) {
  const m = new THREE.Matrix4();
  m.set(c2w[0], c2w[1], c2w[2], c2w[3], c2w[4], c2w[5], c2w[6], c2w[7], c2w[8], c2w[9], c2w[10],
        c2w[11], 0, 0, 0, 1);
  return m;
}

// The four image corners at depth `d` in the camera's frame (OpenCV axes: x right, y down, z
// forward), followed by the centre.
function frustumCorners(cam, d) {
  const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]];
  const pts = corners.map(([u, v]) =>
    new THREE.Vector3(((u - cam.cx) / cam.fx) * d, ((v - cam.cy) / cam.fy) * d, d));
  pts.push(new THREE.Vector3(0, 0, 0));
  return pts;
}

function frustumSegments(cam, d) {
  const p = frustumCorners(cam, d);
  const m = poseMatrix(cam.c2w);
  const w = p.map((q) => q.clone().applyMatrix4(m));
  const c = w[4];
  const seg = [];
  for (let i = 0; i < 4; ++i) seg.push(c, w[i], w[i], w[(i + 1) % 4]);
  return seg;
}

function segmentsGeometry(points) {
  const g = new THREE.BufferGeometry();
  const a = new Float32Array(points.length * 3);
  points.forEach((q, i) => a.set([q.x, q.y, q.z], i * 3));
  g.setAttribute('position', new THREE.BufferAttribute(a, 3));
  return g;
}

function buildTable(el, figures) {
  for (const [label, value] of figures) {
    const tr = document.createElement('tr');
    const th = document.createElement('th');
    th.textContent = label;
    const td = document.createElement('td');
    td.textContent = value;
    tr.append(th, td);
    el.append(tr);
  }
}

function main() {
  const data = JSON.parse(document.getElementById('cvd-data').textContent);
  document.title = data.title;
  document.getElementById('title').textContent = data.title;
  buildTable(document.getElementById('figures'), data.figures);
  for (const w of data.warnings) {
    const li = document.createElement('li');
    li.textContent = w;
    document.getElementById('warnings').append(li);
  }

  const view = document.getElementById('view');
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  view.append(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x15171c);
  // World axes of the run are OpenCV's (y down, z forward); the view turns them y up.
  const world = new THREE.Group();
  world.scale.set(1, -1, -1);
  scene.add(world);

  const n = data.points.count;
  const geometry = new THREE.BufferGeometry();
  const pos = new Float32Array(decodeBase64(data.points.positions).buffer);
  const col = decodeBase64(data.points.colors);
  geometry.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  geometry.setAttribute('color', new THREE.BufferAttribute(col, 3, true));
  geometry.computeBoundingSphere();
  const sphere = n > 0 ? geometry.boundingSphere : new THREE.Sphere(new THREE.Vector3(), 1);
  const size = Math.max(sphere.radius, 1e-6);
  const cloud = new THREE.Points(
    geometry, new THREE.PointsMaterial({ size: size * 0.004, vertexColors: true }));
  world.add(cloud);

  const cams = data.cameras;
  const frustumDepth = size * 0.06;
  const path = [];
  const all = [];
  for (const cam of cams) {
    if (!cam) continue;
    path.push(new THREE.Vector3(cam.c2w[3], cam.c2w[7], cam.c2w[11]));
    all.push(...frustumSegments(cam, frustumDepth));
  }
  if (path.length > 1) {
    world.add(new THREE.Line(segmentsGeometry(path),
                             new THREE.LineBasicMaterial({ color: 0xf2b134 })));
  }
  if (all.length > 0) {
    world.add(new THREE.LineSegments(segmentsGeometry(all),
                                     new THREE.LineBasicMaterial({ color: 0x6f7a8c })));
  }
  const current = new THREE.LineSegments(
    new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xff4d6d }));
  world.add(current);

  const camera = new THREE.PerspectiveCamera(50, 1, size * 1e-3, size * 100);
  const controls = new OrbitControls(camera, renderer.domElement);
  world.updateMatrixWorld();
  const centre = sphere.center.clone().applyMatrix4(world.matrixWorld);
  controls.target.copy(centre);
  // Start behind and above the first camera, looking at the cloud.
  const first = cams.find((c) => c);
  if (first) {
    const eye = new THREE.Vector3(first.c2w[3], first.c2w[7], first.c2w[11]);
    const back = new THREE.Vector3(first.c2w[2], first.c2w[6], first.c2w[10]).multiplyScalar(-size);
    eye.add(back).add(new THREE.Vector3(0, -0.5 * size, 0));
    camera.position.copy(eye.applyMatrix4(world.matrixWorld));
  } else {
    camera.position.copy(centre).add(new THREE.Vector3(0, 0, 2 * size));
  }
  controls.update();

  function resize() {
    const w = view.clientWidth, h = view.clientHeight;
    renderer.setSize(w, h, false);
    renderer.domElement.style.width = w + 'px';
    renderer.domElement.style.height = h + 'px';
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
    render();
  }

  let frames = 0;
  function render() {
    renderer.render(scene, camera);
    frames += 1;
  }
  controls.addEventListener('change', render);

  const slider = document.getElementById('slider');
  const input = document.getElementById('input');
  const depth = document.getElementById('depth');
  const label = document.getElementById('frame-label');
  slider.max = String(Math.max(data.frames.length - 1, 0));
  function setFrame(i) {
    const f = data.frames[i];
    if (!f) return;
    input.src = f.image;
    depth.src = f.depth;
    label.textContent = `${f.name} (${i + 1} of ${data.frames.length})`;
    const cam = cams[f.index];
    current.geometry.dispose();
    current.geometry = cam ? segmentsGeometry(frustumSegments(cam, frustumDepth * 1.5))
                           : new THREE.BufferGeometry();
    slider.value = String(i);
    state.frame = i;
    render();
  }
  const state = { ready: false, frame: -1, setFrame, renders: () => frames };
  window.cvdViewer = state;
  slider.addEventListener('input', () => setFrame(Number(slider.value)));
  window.addEventListener('resize', resize);
  resize();
  setFrame(0);
  state.ready = true;
}

main();
