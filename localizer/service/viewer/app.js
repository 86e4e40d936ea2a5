// The evloc live viewer (docs/viewer.md): a map's points, keyframes and tiles, and the live
// poses, trails and statuses of the sessions from the server's event stream (/api/events).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';

const token = new URLSearchParams(location.hash.slice(1)).get('token');
const headers = token ? { Authorization: 'Bearer ' + token } : {};
const query = new URLSearchParams(location.search);
const statusColours = { TRACKING: 0x44dd44, LOST: 0xff4444, RELOCALIZING: 0xffaa33,
                        INITIALIZING: 0x66aaff, STARTING: 0xaaaaaa };
const maxTrail = 600;

const canvas = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x101418);
const camera = new THREE.PerspectiveCamera(60, 1, 0.01, 5000);
camera.up.set(0, 0, 1);
const controls = new OrbitControls(camera, canvas);
const mapGroup = new THREE.Group();
const sessionGroup = new THREE.Group();
scene.add(mapGroup, sessionGroup, new THREE.AxesHelper(0.5));

const state = { sessions: new Map(), selected: null, points: null, pointData: null, updates: 0 };
document.body.dataset.pointsDrawn = '0';
document.body.dataset.sessionUpdates = '0';
document.body.dataset.frames = '0';

async function getJson(path) {
  const response = await fetch(path, { headers });
  if (!response.ok) throw new Error(path + ': ' + response.status + ' ' + await response.text());
  return response.json();
}

function setConnection(text, error) {
  const element = document.getElementById('connection');
  element.textContent = text;
  element.className = error ? 'error' : '';
}

// A colour map from blue (near) through green to red (far), t in [0, 1].
function rampColour(t, out) {
  const c = Math.min(1, Math.max(0, t));
  out.setHSL((1 - c) * 0.66, 0.9, 0.5);
  return out;
}

function colourPoints() {
  if (!state.points) return;
  const data = state.pointData;
  const count = data.length / 7;
  const colours = state.points.geometry.getAttribute('color');
  const mode = document.getElementById('colour').value;
  const colour = new THREE.Color();
  if (mode === 'depth') {
    // A point's depth in its source keyframe; a point without one (an imported map): its
    // distance from the view's camera when the colours were chosen.
    const depthOf = (i) => Number.isFinite(data[7 * i + 3]) ? data[7 * i + 3] :
        Math.hypot(data[7 * i] - camera.position.x, data[7 * i + 1] - camera.position.y,
                   data[7 * i + 2] - camera.position.z);
    const depths = [];
    for (let i = 0; i < count; ++i) depths.push(depthOf(i));
    depths.sort((a, b) => a - b);
    const low = depths.length ? depths[Math.floor(0.05 * (depths.length - 1))] : 0;
    const high = depths.length ? depths[Math.floor(0.95 * (depths.length - 1))] : 1;
    for (let i = 0; i < count; ++i) {
      rampColour((depthOf(i) - low) / Math.max(1e-6, high - low), colour);
      colours.setXYZ(i, colour.r, colour.g, colour.b);
    }
  } else {
    for (let i = 0; i < count; ++i) {
      colours.setXYZ(i, 0.5 + 0.5 * data[7 * i + 4], 0.5 + 0.5 * data[7 * i + 5],
                     0.5 + 0.5 * data[7 * i + 6]);
    }
  }
  colours.needsUpdate = true;
}

// A camera frustum as line segments (camera frame: x right, y down, z forward).
function frustum(size, colour) {
  const w = size, h = 0.75 * size, d = size;
  const v = [0, 0, 0, -w, -h, d, 0, 0, 0, w, -h, d, 0, 0, 0, w, h, d, 0, 0, 0, -w, h, d,
             -w, -h, d, w, -h, d, w, -h, d, w, h, d, w, h, d, -w, h, d, -w, h, d, -w, -h, d];
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(v, 3));
  return new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: colour }));
}

function place(object, position, rotation) {
  object.position.set(position[0], position[1], position[2]);
  object.quaternion.set(rotation[0], rotation[1], rotation[2], rotation[3]);
}

async function loadMap(name) {
  mapGroup.clear();
  state.points = null;
  const info = await getJson('/api/maps/' + encodeURIComponent(name));
  const min = new THREE.Vector3(...info.box_min), max = new THREE.Vector3(...info.box_max);
  const extent = Math.max(0.5, min.distanceTo(max));
  let drawn = 0;
  if (info.points > 0) {
    const response = await fetch('/api/maps/' + encodeURIComponent(name) + '/points', { headers });
    if (!response.ok) throw new Error('points: ' + response.status);
    const data = new Float32Array(await response.arrayBuffer());
    const count = data.length / 7;
    const positions = new Float32Array(3 * count);
    for (let i = 0; i < count; ++i) positions.set(data.subarray(7 * i, 7 * i + 3), 3 * i);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(3 * count), 3));
    state.pointData = data;
    state.points = new THREE.Points(geometry, new THREE.PointsMaterial({
      size: Math.max(2, 3 * window.devicePixelRatio), sizeAttenuation: false, vertexColors: true }));
    mapGroup.add(state.points);
    drawn = count;
  }
  for (const keyframe of info.keyframes) {
    const marker = frustum(0.02 * extent, 0xffff66);
    place(marker, keyframe.position, keyframe.rotation);
    mapGroup.add(marker);
  }
  for (const tile of info.tiles) {
    const box = new THREE.Box3(new THREE.Vector3(...tile.min), new THREE.Vector3(...tile.max));
    mapGroup.add(new THREE.Box3Helper(box, 0x5588aa));
  }
  document.getElementById('map-info').textContent =
      `${info.name} v${info.version}: ${info.points} points (${drawn} drawn), ` +
      `${info.keyframes.length} keyframes` + (info.site ? `, ${info.tiles.length} tiles` : '');
  document.body.dataset.pointsDrawn = String(drawn);
  const centre = min.clone().add(max).multiplyScalar(0.5);
  controls.target.copy(centre);
  camera.position.copy(centre).add(new THREE.Vector3(-0.6 * extent, -0.9 * extent, 0.7 * extent));
  camera.near = extent / 1000;
  camera.far = extent * 50;
  camera.updateProjectionMatrix();
  controls.update();
  colourPoints();
}

function sessionRow(id) {
  let entry = state.sessions.get(id);
  if (entry) return entry;
  const row = document.createElement('tr');
  row.className = 'session';
  row.dataset.id = String(id);
  row.innerHTML = '<td class="id"></td><td class="client"></td><td class="map"></td>' +
                  '<td class="status"></td><td class="pose"></td>';
  row.querySelector('.id').textContent = String(id);
  row.addEventListener('click', () => selectSession(id));
  document.querySelector('#sessions tbody').appendChild(row);
  const marker = frustum(0.15, statusColours.STARTING);
  marker.visible = false;
  const trailGeometry = new THREE.BufferGeometry();
  trailGeometry.setAttribute('position',
                             new THREE.BufferAttribute(new Float32Array(3 * maxTrail), 3));
  trailGeometry.setDrawRange(0, 0);
  const trail = new THREE.Line(trailGeometry, new THREE.LineBasicMaterial({ color: 0xff66ff }));
  sessionGroup.add(marker, trail);
  entry = { row, marker, trail, trailLength: 0 };
  state.sessions.set(id, entry);
  return entry;
}

function appendTrail(entry, position) {
  const attribute = entry.trail.geometry.getAttribute('position');
  if (entry.trailLength === maxTrail) {
    attribute.array.copyWithin(0, 3);
    entry.trailLength -= 1;
  }
  attribute.setXYZ(entry.trailLength, position[0], position[1], position[2]);
  entry.trailLength += 1;
  attribute.needsUpdate = true;
  entry.trail.geometry.setDrawRange(0, entry.trailLength);
  entry.trail.geometry.computeBoundingSphere();
}

function updateSession(session) {
  const entry = sessionRow(session.id);
  entry.row.querySelector('.client').textContent = session.client;
  entry.row.querySelector('.map').textContent = session.map;
  const status = entry.row.querySelector('.status');
  status.textContent = session.status;
  status.className = 'status ' + session.status;
  entry.row.dataset.status = session.status;
  entry.row.dataset.poses = String(session.poses);
  if (session.position) {
    entry.row.querySelector('.pose').textContent =
        session.position.map((v) => v.toFixed(3)).join(' ');
    entry.row.dataset.t = String(session.t_s);
    place(entry.marker, session.position, session.rotation);
    entry.marker.material.color.setHex(statusColours[session.status] ?? 0xffffff);
    entry.marker.visible = true;
    appendTrail(entry, session.position);
  }
}

function removeEndedSessions(ids) {
  const running = new Set(ids);
  for (const [id, entry] of state.sessions) {
    if (running.has(id)) continue;
    entry.row.remove();
    sessionGroup.remove(entry.marker, entry.trail);
    state.sessions.delete(id);
    if (state.selected === id) selectSession(null);
  }
}

async function refreshSurface() {
  if (state.selected === null) return;
  const id = state.selected;
  try {
    const response = await fetch(`/api/sessions/${id}/surface.png`, { headers });
    if (response.ok && state.selected === id) {
      const image = document.getElementById('surface');
      const previous = image.src;
      image.src = URL.createObjectURL(await response.blob());
      if (previous.startsWith('blob:')) URL.revokeObjectURL(previous);
      image.dataset.loads = String(Number(image.dataset.loads || 0) + 1);
    }
  } finally {
    if (state.selected === id) state.surfaceTimer = setTimeout(refreshSurface, 1000);
  }
}

function selectSession(id) {
  clearTimeout(state.surfaceTimer);
  state.selected = id;
  for (const [other, entry] of state.sessions) entry.row.classList.toggle('selected', other === id);
  document.getElementById('surface-panel').hidden = id === null;
  if (id === null) return;
  document.getElementById('surface-id').textContent = String(id);
  refreshSurface();
}

// The event stream, read with fetch so that it can carry the bearer token; reconnects.
async function followEvents() {
  const rate = query.get('rate') || '30';
  for (;;) {
    try {
      const initial = await getJson('/api/sessions');
      for (const session of initial.sessions) {
        const entry = sessionRow(session.id);
        entry.trailLength = 0;
        for (const position of session.trail) appendTrail(entry, position);
        entry.trailLength = Math.max(0, entry.trailLength - 1);  // updateSession appends the last.
        updateSession(session);
      }
      removeEndedSessions(initial.sessions.map((s) => s.id));
      const response = await fetch('/api/events?rate=' + encodeURIComponent(rate), { headers });
      if (!response.ok) throw new Error('events: ' + response.status + ' ' + await response.text());
      setConnection('live');
      const reader = response.body.getReader();
      const decoder = new TextDecoder();
      let buffer = '';
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += decoder.decode(value, { stream: true });
        let end;
        while ((end = buffer.indexOf('\n\n')) >= 0) {
          const block = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          const data = block.split('\n').filter((l) => l.startsWith('data: ')).map((l) => l.slice(6));
          if (!data.length) continue;
          const event = JSON.parse(data.join('\n'));
          removeEndedSessions(event.ids);
          for (const session of event.sessions) updateSession(session);
          state.updates += 1;
          document.body.dataset.sessionUpdates = String(state.updates);
        }
      }
      setConnection('stream ended; reconnecting', true);
    } catch (error) {
      setConnection(String(error.message || error) + '; reconnecting', true);
    }
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

function resize() {
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (canvas.width !== Math.floor(width * renderer.getPixelRatio()) ||
      canvas.height !== Math.floor(height * renderer.getPixelRatio())) {
    renderer.setSize(width, height, false);
    camera.aspect = width / Math.max(1, height);
    camera.updateProjectionMatrix();
  }
}

let frames = 0;
function animate() {
  resize();
  controls.update();
  renderer.render(scene, camera);
  frames += 1;
  if (frames % 10 === 0) document.body.dataset.frames = String(frames);
  requestAnimationFrame(animate);
}

async function main() {
  document.getElementById('colour').addEventListener('change', colourPoints);
  const select = document.getElementById('map');
  select.addEventListener('change', () => loadMap(select.value).catch(
      (error) => setConnection(String(error.message || error), true)));
  animate();
  followEvents();
  const { maps } = await getJson('/api/maps');
  for (const name of maps) select.add(new Option(name, name));
  const wanted = query.get('map');
  if (wanted && maps.includes(wanted)) select.value = wanted;
  if (select.value) await loadMap(select.value);
  document.body.dataset.ready = '1';
}

main().catch((error) => setConnection(String(error.message || error), true));
