// The mogen 3-D viewer: draws the motions in #viewer-data with three.js (the global `THREE`
// from three.min.js, built by build.sh). A classic script, not a module: pages opened from
// file:// cannot import sibling files.
//
// Data (written by motion-core/src/export/viewer.rs):
//   { title, fps, joints: [22 names], parents: [22 parent indices, null for the pelvis],
//     samples: [{ label, frames: [frame][22][x, y, z] }], scene: [SceneBox],
//     carried: [{ hands: [joint, joint], diameter_m }], report: TaskReport|null,
//     rigs: [{ label, glb_base64 }] }
// A rig is a sample on the user's rig (`--rig`): its GLB is read by THREE.GLTFLoader and its
// skinned body played by an AnimationMixer at the page's time (the GLB's scene boxes, meshes
// under no bone, are left hidden: the page draws its own). `window.mogenRigsShown` counts the
// rigs on stage.
// Axes are the project's and three.js's own: metres, y up, the character starts facing +z and
// +x is its left, so positions go in unchanged.
'use strict';

(function main() {
  const LEFT = 0x2850dc;
  const RIGHT = 0xdc3228;
  const CARRIED = 0xe6961e;
  // Mid-line colours per sample (left and right limbs stay blue and red in every sample).
  const PALETTE = [0x3a3f47, 0x1e8449, 0x8e44ad, 0xd68910, 0x16a085, 0x7b241c];
  const SCENE_STYLE = {
    obstacle: { fill: 0xc0504d, opacity: 0.3, edge: 0x8b2e2b, label: 'obstacle (must not enter)' },
    region: { fill: 0x1e8449, opacity: 0.12, edge: 0x1e8449, label: 'region (stay inside)' },
    support: { fill: 0x8b5a2b, opacity: 1.0, edge: 0x5e3b1a, label: 'support (stand on)' },
    target: { fill: 0x2e9d4f, opacity: 0.5, edge: 0x1e6b34, label: 'target (reach it)' },
  };
  const UNITS = { m: ' m', m_per_s: ' m/s', m_per_s2: ' m/s²', deg: '°', count: '' };
  const DECIMALS = { m: 3, m_per_s: 2, m_per_s2: 2, deg: 1, count: 0 };
  const JOINT_RADIUS_M = 0.032;
  const HEAD_RADIUS_M = 0.09;
  const BONE_RADIUS_M = 0.022;

  const $ = (id) => document.getElementById(id);
  const hex = (colour) => '#' + colour.toString(16).padStart(6, '0');

  function fail(message) {
    const box = $('error');
    box.textContent = 'The viewer cannot draw: ' + message;
    box.style.display = 'block';
    console.error('mogen viewer: ' + message);
  }

  let data;
  try {
    data = JSON.parse($('viewer-data').textContent);
  } catch (e) {
    fail('the embedded data does not parse (' + e.message + ')');
    return;
  }
  if (typeof THREE === 'undefined') {
    fail('three.js is missing from the page');
    return;
  }
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true });
  } catch (e) {
    fail('WebGL is not available in this browser (' + e.message + ')');
    return;
  }

  const joints = data.joints;
  const side = joints.map((name) => (name.startsWith('left_') ? 'left' : name.startsWith('right_') ? 'right' : 'mid'));
  const bones = data.parents.flatMap((parent, child) => (parent === null ? [] : [[parent, child]]));
  const PELVIS = joints.indexOf('pelvis');
  const HEAD = joints.indexOf('head');
  const FEET = [joints.indexOf('left_foot'), joints.indexOf('right_foot')];
  const lastFrame = Math.max(...data.samples.map((s) => s.frames.length)) - 1;

  document.title = data.title + ' · mogen viewer';
  $('title').textContent = data.title;

  // Renderer, scene, lights.
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.autoClear = false; // the axes gizmo is drawn over the scene
  renderer.shadowMap.enabled = true;
  renderer.shadowMap.type = THREE.PCFShadowMap;
  $('stage').appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xeef0f3);
  scene.add(new THREE.HemisphereLight(0xffffff, 0xb8bcc4, 1.6));

  // The region every joint of every sample visits, m.
  const lo = new THREE.Vector3(Infinity, Infinity, Infinity);
  const hi = new THREE.Vector3(-Infinity, -Infinity, -Infinity);
  const point = new THREE.Vector3();
  for (const sample of data.samples) {
    for (const frame of sample.frames) {
      for (const p of frame) {
        lo.min(point.fromArray(p));
        hi.max(point);
      }
    }
  }
  lo.y = Math.min(lo.y, 0);
  const centre = lo.clone().add(hi).multiplyScalar(0.5);
  const radius = Math.max(1.0, lo.distanceTo(hi) / 2);

  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(centre.x - 2, hi.y + 6, centre.z - 3);
  sun.target.position.copy(centre);
  sun.castShadow = true;
  sun.shadow.mapSize.set(2048, 2048);
  const shadowCamera = sun.shadow.camera;
  shadowCamera.left = shadowCamera.bottom = -(radius + 1);
  shadowCamera.right = shadowCamera.top = radius + 1;
  shadowCamera.far = 40;
  scene.add(sun, sun.target);

  // Ground: a floor, 0.5 m grid lines (darker every metre, darkest on the axes), metre labels.
  const x0 = Math.floor(lo.x - 0.5);
  const x1 = Math.ceil(hi.x + 0.5);
  const z0 = Math.floor(lo.z - 0.5);
  const z1 = Math.ceil(hi.z + 0.5);
  const floor = new THREE.Mesh(
    new THREE.PlaneGeometry(x1 - x0, z1 - z0),
    new THREE.MeshStandardMaterial({ color: 0xf7f8fa, roughness: 1 }),
  );
  floor.rotation.x = -Math.PI / 2;
  floor.position.set((x0 + x1) / 2, 0, (z0 + z1) / 2);
  floor.receiveShadow = true;
  scene.add(floor);

  const segments = (points, colour) =>
    new THREE.LineSegments(new THREE.BufferGeometry().setFromPoints(points), new THREE.LineBasicMaterial({ color: colour }));
  const grid = { minor: [], major: [], axis: [] };
  const kind = (v) => (v === 0 ? 'axis' : Number.isInteger(v) ? 'major' : 'minor');
  const Y_GRID = 0.002;
  for (let x = x0; x <= x1; x += 0.5) {
    grid[kind(x)].push(new THREE.Vector3(x, Y_GRID, z0), new THREE.Vector3(x, Y_GRID, z1));
  }
  for (let z = z0; z <= z1; z += 0.5) {
    grid[kind(z)].push(new THREE.Vector3(x0, Y_GRID, z), new THREE.Vector3(x1, Y_GRID, z));
  }
  scene.add(segments(grid.minor, 0xc9ced6), segments(grid.major, 0x9aa1ad), segments(grid.axis, 0x5d6675));

  function textSprite(text, heightM, colour) {
    const canvas = document.createElement('canvas');
    const context = canvas.getContext('2d');
    const px = 48;
    context.font = `600 ${px}px system-ui, "DejaVu Sans", sans-serif`;
    canvas.width = Math.ceil(context.measureText(text).width) + 16;
    canvas.height = px + 16;
    context.font = `600 ${px}px system-ui, "DejaVu Sans", sans-serif`;
    context.fillStyle = colour;
    context.textBaseline = 'middle';
    context.fillText(text, 8, canvas.height / 2);
    const texture = new THREE.CanvasTexture(canvas);
    texture.colorSpace = THREE.SRGBColorSpace;
    const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: texture, depthWrite: false }));
    sprite.scale.set((heightM * canvas.width) / canvas.height, heightM, 1);
    return sprite;
  }
  const LABEL_M = 0.16;
  for (let x = x0; x <= x1; x += 1) {
    const label = textSprite(`x ${x} m`, LABEL_M, '#5d6675');
    label.position.set(x, 0.06, z0 - 0.2);
    scene.add(label);
  }
  for (let z = z0 + 1; z <= z1; z += 1) {
    const label = textSprite(`z ${z} m`, LABEL_M, '#5d6675');
    label.position.set(x0 - 0.35, 0.06, z);
    scene.add(label);
  }

  // Scene boxes.
  const rolesPresent = new Set();
  for (const box of data.scene) {
    const style = SCENE_STYLE[box.role];
    if (!style) continue;
    rolesPresent.add(box.role);
    const [hx, hy, hz] = box.half_extents_m;
    const geometry = new THREE.BoxGeometry(2 * hx, 2 * hy, 2 * hz);
    const opaque = style.opacity >= 1;
    const mesh = new THREE.Mesh(
      geometry,
      new THREE.MeshStandardMaterial({
        color: style.fill, roughness: 0.8, transparent: !opaque, opacity: style.opacity, depthWrite: opaque,
      }),
    );
    mesh.castShadow = opaque;
    mesh.receiveShadow = true;
    mesh.add(new THREE.LineSegments(new THREE.EdgesGeometry(geometry), new THREE.LineBasicMaterial({ color: style.edge })));
    mesh.position.fromArray(box.centre_m);
    mesh.quaternion.fromArray(box.rotation_xyzw);
    mesh.name = box.name;
    scene.add(mesh);
  }

  // Figures: joints as spheres, bones as cylinders (unit cylinders along y, stretched per frame).
  const sphere = new THREE.SphereGeometry(1, 16, 12);
  const cylinder = new THREE.CylinderGeometry(1, 1, 1, 12, 1);
  const material = (colour) => new THREE.MeshStandardMaterial({ color: colour, roughness: 0.55 });
  const UP = new THREE.Vector3(0, 1, 0);

  const figures = data.samples.map((sample, index) => {
    const mid = PALETTE[index % PALETTE.length];
    const materials = { left: material(LEFT), right: material(RIGHT), mid: material(mid) };
    const group = new THREE.Group();
    const jointMeshes = joints.map((_, j) => {
      const mesh = new THREE.Mesh(sphere, materials[side[j]]);
      mesh.scale.setScalar(j === HEAD ? HEAD_RADIUS_M : JOINT_RADIUS_M);
      mesh.castShadow = true;
      group.add(mesh);
      return mesh;
    });
    const boneMeshes = bones.map(([, child]) => {
      const mesh = new THREE.Mesh(cylinder, materials[side[child]]);
      mesh.castShadow = true;
      group.add(mesh);
      return mesh;
    });
    // Trajectories: the pelvis in the sample's colour, the feet in their sides' colours.
    const track = (joint, colour, opacity) => {
      const points = sample.frames.map((frame) => new THREE.Vector3().fromArray(frame[joint]));
      const geometry = new THREE.BufferGeometry().setFromPoints(points);
      return new THREE.Line(geometry, new THREE.LineBasicMaterial({ color: colour, transparent: true, opacity }));
    };
    group.add(track(PELVIS, mid, 0.9), track(FEET[0], LEFT, 0.55), track(FEET[1], RIGHT, 0.55));
    const label = textSprite(sample.label, 0.12, hex(mid));
    group.add(label);
    scene.add(group);
    const positions = joints.map(() => new THREE.Vector3());
    // Objects carried between the hands: a translucent ball of the object's diameter.
    const balls = (data.carried || []).map((object) => {
      const mesh = new THREE.Mesh(
        sphere,
        new THREE.MeshStandardMaterial({ color: CARRIED, roughness: 0.6, transparent: true, opacity: 0.55 }),
      );
      mesh.scale.setScalar(object.diameter_m / 2);
      mesh.name = 'carried object';
      group.add(mesh);
      return { mesh, hands: object.hands };
    });
    return { sample, index, group, jointMeshes, boneMeshes, balls, label, positions, colour: mid };
  });

  /** Whether a bone lies above `object` in its tree. */
  function boneAbove(object) {
    for (let up = object.parent; up; up = up.parent) if (up.isBone) return true;
    return false;
  }
  // Each sample on the user's rig, where the rig stands.
  const mixers = [];
  window.mogenRigsShown = 0;
  for (const rig of data.rigs || []) {
    const bytes = Uint8Array.from(atob(rig.glb_base64), (c) => c.charCodeAt(0));
    new THREE.GLTFLoader().parse(
      bytes.buffer,
      '',
      (gltf) => {
        gltf.scene.traverse((object) => {
          if (object.isSkinnedMesh) {
            object.castShadow = true;
            object.frustumCulled = false; // the skin moves the body far from its bind box
          } else if (object.isMesh && !boneAbove(object)) {
            object.visible = false; // a scene box of our rig GLB; a prop on a bone stays
          }
        });
        const label = textSprite(rig.label, 0.12, '#555555');
        gltf.scene.add(label);
        scene.add(gltf.scene);
        const mixer = new THREE.AnimationMixer(gltf.scene);
        gltf.animations.forEach((clip) => mixer.clipAction(clip).play());
        mixers.push({ mixer, label, root: gltf.scene.getObjectByProperty('type', 'Bone') });
        window.mogenRigsShown += 1;
      },
      (error) => fail(`the GLB of ${rig.label} cannot be read (${error && error.message ? error.message : error})`),
    );
  }
  const rigLabelAt = new THREE.Vector3();
  const RIG_LABEL_M = 2.1; // above a person-sized rig and the sample's own label
  /** Poses every rig at `frame` (the GLB's time is the motion's: frame / fps seconds). */
  function poseRigs(frame) {
    for (const { mixer, label, root } of mixers) {
      mixer.setTime(frame / data.fps);
      if (root) {
        root.getWorldPosition(rigLabelAt);
        label.position.set(rigLabelAt.x, RIG_LABEL_M, rigLabelAt.z);
      }
    }
  }

  const direction = new THREE.Vector3();
  /** Poses a figure at `frame` (fractional: joint positions interpolated linearly). */
  function pose(figure, frame) {
    const frames = figure.sample.frames;
    const f = Math.min(frame, frames.length - 1);
    const i = Math.floor(f);
    const a = f - i;
    const next = frames[Math.min(i + 1, frames.length - 1)];
    figure.positions.forEach((p, j) => p.fromArray(frames[i][j]).lerp(direction.fromArray(next[j]), a));
    figure.jointMeshes.forEach((mesh, j) => mesh.position.copy(figure.positions[j]));
    figure.boneMeshes.forEach((mesh, b) => {
      const [parent, child] = bones[b];
      const from = figure.positions[parent];
      const to = figure.positions[child];
      direction.subVectors(to, from);
      const length = direction.length();
      mesh.position.addVectors(from, to).multiplyScalar(0.5);
      mesh.scale.set(BONE_RADIUS_M, Math.max(length, 1e-6), BONE_RADIUS_M);
      if (length > 1e-9) mesh.quaternion.setFromUnitVectors(UP, direction.divideScalar(length));
    });
    figure.balls.forEach((ball) => {
      ball.mesh.position.addVectors(figure.positions[ball.hands[0]], figure.positions[ball.hands[1]]).multiplyScalar(0.5);
    });
    figure.label.position.copy(figure.positions[HEAD]);
    // Stacked by sample, so figures that start together keep readable labels.
    figure.label.position.y += 0.25 + 0.16 * figure.index;
  }

  // Camera: from the character's right and front, far enough to hold every joint.
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 500);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  const distance = (0.75 * radius) / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2));
  controls.target.set(centre.x, Math.max(0.8, centre.y * 0.8), centre.z);
  camera.position.copy(controls.target).add(new THREE.Vector3(-0.85, 0.4, 0.32).normalize().multiplyScalar(distance));
  controls.enableDamping = true;
  controls.update();

  // Axes gizmo in the lower left corner, turning with the camera (#gizmo spells the axes out).
  // CSS px from the lower left, as #gizmo: a square for the arrows over a caption strip.
  const GIZMO = { left: 12, bottom: 96, size: 160, caption: 22 };
  const gizmo = new THREE.Scene();
  for (const [axis, text] of [
    [new THREE.Vector3(1, 0, 0), '+x'],
    [new THREE.Vector3(0, 1, 0), '+y'],
    [new THREE.Vector3(0, 0, 1), '+z'],
  ]) {
    gizmo.add(new THREE.ArrowHelper(axis, new THREE.Vector3(), 0.6, 0x1f2430, 0.16, 0.08));
    const label = textSprite(text, 0.2, '#1f2430');
    label.position.copy(axis).multiplyScalar(0.78);
    gizmo.add(label);
  }
  const gizmoCamera = new THREE.PerspectiveCamera(35, 1, 0.1, 20);
  function renderGizmo() {
    gizmoCamera.position.set(0, 0, 3.3).applyQuaternion(camera.quaternion);
    gizmoCamera.quaternion.copy(camera.quaternion);
    renderer.setScissorTest(true);
    renderer.setScissor(GIZMO.left, GIZMO.bottom - GIZMO.caption, GIZMO.size, GIZMO.size + GIZMO.caption);
    renderer.setClearColor(0xffffff);
    renderer.clear();
    renderer.setViewport(GIZMO.left, GIZMO.bottom, GIZMO.size, GIZMO.size);
    renderer.render(gizmo, gizmoCamera);
    renderer.setScissorTest(false);
    renderer.setViewport(0, 0, window.innerWidth, window.innerHeight);
  }

  function resize() {
    const width = window.innerWidth;
    const height = window.innerHeight;
    renderer.setSize(width, height);
    camera.aspect = width / Math.max(height, 1);
    camera.updateProjectionMatrix();
  }
  window.addEventListener('resize', resize);
  resize();

  // Legend: sample colours, limb sides, scene roles, axes.
  const legend = $('legend');
  const legendRow = (colour, text, outline) => {
    const row = document.createElement('div');
    row.className = 'row';
    const swatch = document.createElement('span');
    swatch.className = 'swatch';
    swatch.style.background = outline ? 'transparent' : colour;
    if (outline) swatch.style.border = '2px solid ' + colour;
    const words = document.createElement('span');
    words.textContent = text;
    row.append(swatch, words);
    legend.appendChild(row);
  };
  figures.forEach((f) => legendRow(hex(f.colour), f.sample.label + ': mid-line and pelvis path'));
  legendRow(hex(LEFT), 'left limbs and left foot path');
  legendRow(hex(RIGHT), 'right limbs and right foot path');
  if ((data.carried || []).length > 0) legendRow(hex(CARRIED), 'carried object (between the hands)');
  for (const role of ['obstacle', 'region', 'support', 'target']) {
    if (rolesPresent.has(role)) legendRow(hex(SCENE_STYLE[role].fill), SCENE_STYLE[role].label, role === 'region');
  }
  const axes = document.createElement('div');
  axes.textContent = `Metres, y up; the character starts facing +z, +x is its left. ${data.fps} fps. ` +
    'Drag to orbit, right-drag to pan, wheel to zoom; space plays or pauses, arrows step.';
  axes.style.marginTop = '4px';
  legend.appendChild(axes);

  // Sample switch.
  const select = $('sample');
  const option = (value, text) => {
    const o = document.createElement('option');
    o.value = value;
    o.textContent = text;
    select.appendChild(o);
  };
  if (figures.length > 1) option('all', 'all');
  figures.forEach((f, i) => option(String(i), f.sample.label));
  select.addEventListener('change', () => {
    figures.forEach((f, i) => { f.group.visible = select.value === 'all' || select.value === String(i); });
    renderReport();
  });

  // Playback.
  const state = { frame: 0, playing: true, speed: 1 };
  const play = $('play');
  const scrub = $('scrub');
  scrub.max = String(lastFrame);
  const setPlaying = (playing) => {
    state.playing = playing && lastFrame > 0;
    play.textContent = state.playing ? 'Pause' : 'Play';
  };
  setPlaying(true);
  play.addEventListener('click', () => setPlaying(!state.playing));
  scrub.addEventListener('input', () => {
    setPlaying(false);
    state.frame = Number(scrub.value);
  });
  $('speed').addEventListener('change', (e) => { state.speed = Number(e.target.value); });
  window.addEventListener('keydown', (e) => {
    // Focused controls handle their own keys (a focused button already toggles on space).
    if (e.target instanceof Element && e.target.closest('button, input, select')) return;
    if (e.code === 'Space') {
      setPlaying(!state.playing);
      e.preventDefault();
    } else if (e.code === 'ArrowRight' || e.code === 'ArrowLeft') {
      setPlaying(false);
      const step = e.code === 'ArrowRight' ? 1 : -1;
      state.frame = Math.min(lastFrame, Math.max(0, Math.round(state.frame) + step));
    }
  });

  // The per-constraint report.
  const element = (tag, text, className) => {
    const e = document.createElement(tag);
    if (text !== undefined) e.textContent = text;
    if (className) e.className = className;
    return e;
  };
  const formatValue = (value, unit) => {
    if (typeof value !== 'number') return String(value);
    return value.toFixed(DECIMALS[unit] ?? 3) + (UNITS[unit] ?? ' ' + unit);
  };
  function renderReport() {
    const panel = $('report');
    panel.replaceChildren();
    const details = element('details');
    details.open = true;
    panel.appendChild(details);
    details.appendChild(element('summary', 'Constraints'));
    const report = data.report;
    if (!report || typeof report !== 'object') {
      details.appendChild(element('p', 'No task report: this motion was exported without a task.'));
      return;
    }
    if (report.text) details.appendChild(element('div', '“' + report.text + '”', 'prompt'));
    const facts = [];
    if (typeof report.success_rate === 'number') facts.push(`success ${(100 * report.success_rate).toFixed(0)}%`);
    if (typeof report.constraint_error === 'number') facts.push(`constraint error ${report.constraint_error.toPrecision(3)}`);
    if (typeof report.max_scene_penetration_m === 'number') facts.push(`max scene penetration ${formatValue(report.max_scene_penetration_m, 'm')}`);
    if (typeof report.foot_skate_ratio === 'number') facts.push(`foot skate ${report.foot_skate_ratio.toFixed(3)}`);
    if (facts.length) details.appendChild(element('div', facts.join(' · '), 'figures'));
    const constraints = Array.isArray(report.constraints) ? report.constraints : [];
    if (!constraints.length) {
      details.appendChild(element('p', 'The report lists no constraints.'));
      return;
    }
    const count = Math.max(1, ...constraints.map((c) => (Array.isArray(c.pass) ? c.pass.length : 0)));
    const columns = [...Array(count).keys()];
    const shown = (s) => select.value === 'all' || select.value === String(s);
    const name = (s) => (count === figures.length ? figures[s].sample.label : `sample ${s}`);
    const table = element('table');
    const head = element('tr');
    head.append(element('th', 'constraint / check'), element('th', 'tolerance'));
    columns.forEach((s) => head.appendChild(element('th', name(s), shown(s) ? '' : 'dim')));
    table.appendChild(head);
    for (const c of constraints) {
      const row = element('tr', undefined, 'constraint');
      row.append(element('td', c.id + (c.description ? ': ' + c.description : '')), element('td', ''));
      columns.forEach((s) => {
        const pass = Array.isArray(c.pass) ? c.pass[s] : undefined;
        const text = pass === true ? '✓ pass' : pass === false ? '✗ fail' : '–';
        const cls = (pass === true ? 'pass' : pass === false ? 'fail' : '') + (shown(s) ? '' : ' dim');
        row.appendChild(element('td', text, 'num ' + cls));
      });
      table.appendChild(row);
      for (const check of Array.isArray(c.checks) ? c.checks : []) {
        const line = element('tr');
        line.append(element('td', check.what), element('td', '≤ ' + formatValue(check.tolerance, check.unit), 'num'));
        columns.forEach((s) => {
          const value = Array.isArray(check.value) ? check.value[s] : undefined;
          const ok = typeof value === 'number' && value <= check.tolerance;
          const cls = (value === undefined ? '' : ok ? 'pass' : 'fail') + (shown(s) ? '' : ' dim');
          line.appendChild(element('td', value === undefined ? '–' : formatValue(value, check.unit), 'num ' + cls));
        });
        table.appendChild(line);
      }
    }
    details.appendChild(table);
  }
  renderReport();

  // The loop.
  const readout = $('readout');
  let previousMs = performance.now();
  const seconds = (frame) => (frame / data.fps).toFixed(2);
  function animate() {
    const nowMs = performance.now();
    const dt = Math.min((nowMs - previousMs) / 1000, 0.1);
    previousMs = nowMs;
    if (state.playing) {
      state.frame += dt * data.fps * state.speed;
      if (state.frame > lastFrame) state.frame %= lastFrame;
      scrub.value = String(Math.round(state.frame));
    }
    figures.forEach((f) => pose(f, state.frame));
    poseRigs(state.frame);
    const shownFrame = Math.round(state.frame);
    readout.textContent = `frame ${shownFrame} / ${lastFrame} · ${seconds(shownFrame)} s / ${seconds(lastFrame)} s`;
    controls.update();
    renderer.clear();
    renderer.render(scene, camera);
    renderGizmo();
  }
  renderer.setAnimationLoop(animate);
})();
