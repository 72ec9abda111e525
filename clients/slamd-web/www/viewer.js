// slamd-web browser viewer: renders the state streamed by the slamd-web server over /ws
// (protocol: version 1). Requires three.js r111 (global THREE) and THREE.OrbitControls.
'use strict';

(function () {
  const MAX_TRAIL_POSES = 100000;
  const CAMERA_FRUSTUM_DEPTH_M = 0.15;
  const KEYFRAME_FRUSTUM_DEPTH_M = 0.06;
  const FRUSTUM_HORIZONTAL_FOV_RAD = 60 * Math.PI / 180;
  const FRUSTUM_ASPECT = 4 / 3;
  const VANISHING_POINT_LENGTH_M = 1.0;
  const STATUS_STALE_S = 3;
  const OCCUPANCY_REDRAW_INTERVAL_MS = 250;
  const MAX_RENDER_INTERVAL_MS = 1000;
  const RECONNECT_DELAY_MS = 1000;
  const FULL_STATE_FALLBACK_MS = 2000;
  const MALFORMED_RESYNC_INTERVAL_MS = 2000;
  const VOXEL_KEY_OFFSET = 32768;
  const VOXEL_HEADER_BYTES = 16;
  const VOXEL_RECORD_BYTES = 8;
  const VOXEL_KIND_REPLACE = 1;
  const VOXEL_KIND_CHANGES = 2;
  const VIEW_FOV_DEG = 60;
  // Voxel points are drawn slightly larger than a voxel so that pixel rounding leaves no holes.
  const VOXEL_POINT_OVERLAP = 1.2;

  // Tracking state -> colour (0 not initialised, 1 ok, 2 predicted, 3 lost, 4 relocalised).
  const STATE_COLOURS = [0x9e9e9e, 0x33dd55, 0xffb000, 0xff3b3b, 0x3c9cff].map((hex) => new THREE.Color(hex));
  const stateColour = (state) => STATE_COLOURS[state] || STATE_COLOURS[0];
  const KEYFRAME_COLOUR = 0xc8b4ff;
  const VP_ACCEPTED_COLOUR = new THREE.Color(0xff40ff);
  const VP_REJECTED_COLOUR = new THREE.Color(0x555a60);

  // How the world's up axis maps to the display (three.js, y up). Every rotation is about x, so
  // display x = world x; display y (height) and display z (depth) are a world axis times a sign.
  const UP_AXES = {
    '-y': { rotationX_rad: Math.PI, heightAxis: 1, heightSign: -1, depthAxis: 2, depthSign: -1 },
    'y': { rotationX_rad: 0, heightAxis: 1, heightSign: 1, depthAxis: 2, depthSign: 1 },
    'z': { rotationX_rad: -Math.PI / 2, heightAxis: 2, heightSign: 1, depthAxis: 1, depthSign: -1 },
    '-z': { rotationX_rad: Math.PI / 2, heightAxis: 2, heightSign: -1, depthAxis: 1, depthSign: 1 },
  };
  // slamd spells them as mapping.up_axis does; an x axis up is not shown (the page falls back to
  // -y and says so in its header).
  UP_AXES['+y'] = UP_AXES['y'];
  UP_AXES['+z'] = UP_AXES['z'];

  // Height colour ramp: blue -> green -> yellow -> red.
  const RAMP_STOPS = [[0.15, 0.35, 1.0], [0.1, 0.85, 0.35], [1.0, 0.9, 0.1], [1.0, 0.25, 0.1]];
  function writeRampColour(t, out, offset) {
    const s = Math.min(Math.max(t, 0), 1) * (RAMP_STOPS.length - 1);
    const i = Math.min(Math.floor(s), RAMP_STOPS.length - 2);
    const f = s - i;
    const a = RAMP_STOPS[i];
    const b = RAMP_STOPS[i + 1];
    out[offset] = a[0] + (b[0] - a[0]) * f;
    out[offset + 1] = a[1] + (b[1] - a[1]) * f;
    out[offset + 2] = a[2] + (b[2] - a[2]) * f;
  }

  const $ = (id) => document.getElementById(id);
  const escapeHtml = (value) => String(value).replace(/[&<>"']/g,
    (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));
  const formatNumber = (value, digits) =>
    (typeof value === 'number' && Number.isFinite(value) ? value.toFixed(digits) : '-');
  // Resident memory, and the limit with the level slamd degrades by (status_t.memory_pressure).
  const memoryText = (s) => {
    const resident = `${formatNumber(s.memory_rss_mb, 0)} MB`;
    if (!(s.memory_limit_mb > 0)) return `${resident} (no limit)`;
    const levels = ['under the limit', 'near the limit: degrading', 'over the limit: degrading'];
    const level = levels[s.memory_pressure] || `pressure ${s.memory_pressure}`;
    return `${resident} of ${s.memory_limit_mb} MB, ${level}`;
  };

  // ---------------------------------------------------------------------------------------------
  // Growable position + colour vertex storage for one BufferGeometry. Capacity grows by doubling;
  // uploads only the vertex range marked dirty, once per animation frame.
  class VertexBuffer {
    constructor(initialCapacityVertices) {
      this.geometry = new THREE.BufferGeometry();
      this.positions = new Float32Array(0);
      this.colours = new Float32Array(0);
      this.capacity = 0;
      this.dirtyFrom = Infinity;
      this.dirtyTo = 0;
      this.allocate(initialCapacityVertices, 0);
    }

    allocate(capacityVertices, keepVertices) {
      const positions = new Float32Array(capacityVertices * 3);
      const colours = new Float32Array(capacityVertices * 3);
      positions.set(this.positions.subarray(0, keepVertices * 3));
      colours.set(this.colours.subarray(0, keepVertices * 3));
      // Frees the GPU buffers of the old (smaller) attributes; new ones are created on next render.
      this.geometry.dispose();
      this.geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3).setUsage(THREE.DynamicDrawUsage));
      this.geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3).setUsage(THREE.DynamicDrawUsage));
      this.positions = positions;
      this.colours = colours;
      this.capacity = capacityVertices;
      this.dirtyFrom = Infinity;
      this.dirtyTo = 0;
      this.markDirty(0, keepVertices);
    }

    ensureCapacity(vertices, keepVertices) {
      if (vertices <= this.capacity) return;
      let capacity = Math.max(this.capacity, 1);
      while (capacity < vertices) capacity *= 2;
      this.allocate(capacity, keepVertices);
    }

    markDirty(fromVertex, toVertex) {
      this.dirtyFrom = Math.min(this.dirtyFrom, fromVertex);
      this.dirtyTo = Math.max(this.dirtyTo, toVertex);
    }

    // Returns true if anything was scheduled for upload.
    upload() {
      if (this.dirtyFrom >= this.dirtyTo) return false;
      for (const name of ['position', 'color']) {
        const attribute = this.geometry.attributes[name];
        attribute.updateRange.offset = this.dirtyFrom * 3;
        attribute.updateRange.count = (this.dirtyTo - this.dirtyFrom) * 3;
        attribute.needsUpdate = true;
      }
      this.dirtyFrom = Infinity;
      this.dirtyTo = 0;
      return true;
    }
  }

  // Line segments of a camera frustum in the optical frame (opens along +z, image up is -y),
  // as a flat [x0,y0,z0, x1,y1,z1, ...] list; withUpMarker adds a small triangle on the top edge.
  function frustumSegments(depth_m, withUpMarker) {
    const w = depth_m * Math.tan(FRUSTUM_HORIZONTAL_FOV_RAD / 2);
    const h = w / FRUSTUM_ASPECT;
    const d = depth_m;
    const corners = [[-w, -h, d], [w, -h, d], [w, h, d], [-w, h, d]];
    const segments = [];
    for (let i = 0; i < 4; i++) {
      segments.push(0, 0, 0, ...corners[i]);
      segments.push(...corners[i], ...corners[(i + 1) % 4]);
    }
    if (withUpMarker) {
      segments.push(-w * 0.5, -h, d, 0, -h * 1.7, d);
      segments.push(0, -h * 1.7, d, w * 0.5, -h, d);
    }
    return segments;
  }
  const KEYFRAME_FRUSTUM = frustumSegments(KEYFRAME_FRUSTUM_DEPTH_M, false);
  const KEYFRAME_FRUSTUM_VERTICES = KEYFRAME_FRUSTUM.length / 3;

  const quaternionFromWxyz = (q, out) => out.set(q[1], q[2], q[3], q[0]);

  // ---------------------------------------------------------------------------------------------
  // Scene
  const view3d = $('view3d');
  const renderer = new THREE.WebGLRenderer({ antialias: false });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  renderer.setClearColor(0x111418);
  view3d.insertBefore(renderer.domElement, view3d.firstChild);

  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(VIEW_FOV_DEG, 1, 0.01, 5000);
  camera.position.set(3, 4, 6);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.screenSpacePanning = true;

  // All world-frame content lives in worldGroup, rotated so that the world's up axis is display +y.
  const worldGroup = new THREE.Group();
  scene.add(worldGroup);

  const voxelBuffer = new VertexBuffer(65536);
  const voxelMaterial = new THREE.PointsMaterial({ size: 0.05, sizeAttenuation: true, vertexColors: THREE.VertexColors });
  const voxelPoints = new THREE.Points(voxelBuffer.geometry, voxelMaterial);

  const trailBuffer = new VertexBuffer(1024);
  const trailLine = new THREE.Line(trailBuffer.geometry, new THREE.LineBasicMaterial({ vertexColors: THREE.VertexColors }));

  const keyframeFrustaBuffer = new VertexBuffer(256 * KEYFRAME_FRUSTUM_VERTICES);
  const keyframeFrustaLines = new THREE.LineSegments(keyframeFrustaBuffer.geometry,
    new THREE.LineBasicMaterial({ color: KEYFRAME_COLOUR }));
  const keyframePathBuffer = new VertexBuffer(256);
  const keyframePathLine = new THREE.Line(keyframePathBuffer.geometry,
    new THREE.LineBasicMaterial({ color: KEYFRAME_COLOUR, transparent: true, opacity: 0.6 }));

  // The newest camera: frustum plus vanishing point directions, both in the camera's optical frame.
  const newestCameraGroup = new THREE.Group();
  const frustumGeometry = new THREE.BufferGeometry();
  frustumGeometry.setAttribute('position', new THREE.Float32BufferAttribute(frustumSegments(CAMERA_FRUSTUM_DEPTH_M, true), 3));
  const frustumMaterial = new THREE.LineBasicMaterial({ color: stateColour(0) });
  newestCameraGroup.add(new THREE.LineSegments(frustumGeometry, frustumMaterial));
  // A fixed-size dot at the camera centre keeps the small frustum findable from far away.
  const cameraDotGeometry = new THREE.BufferGeometry();
  cameraDotGeometry.setAttribute('position', new THREE.Float32BufferAttribute([0, 0, 0], 3));
  const cameraDotMaterial = new THREE.PointsMaterial({ size: 7, sizeAttenuation: false, color: stateColour(0) });
  newestCameraGroup.add(new THREE.Points(cameraDotGeometry, cameraDotMaterial));
  const vanishingPointBuffer = new VertexBuffer(32);
  const vanishingPointLines = new THREE.LineSegments(vanishingPointBuffer.geometry,
    new THREE.LineBasicMaterial({ vertexColors: THREE.VertexColors }));
  newestCameraGroup.add(vanishingPointLines);

  for (const object of [voxelPoints, trailLine, keyframeFrustaLines, keyframePathLine, vanishingPointLines]) {
    object.frustumCulled = false; // bounding spheres would go stale as the buffers change
  }
  worldGroup.add(voxelPoints, trailLine, keyframeFrustaLines, keyframePathLine, newestCameraGroup);

  let groundGrid = null;

  // ---------------------------------------------------------------------------------------------
  // Page state
  const world = { frameId: '-', resolution_m: 0.05, upAxisName: '-y', up: UP_AXES['-y'] };

  // Occupied voxels: a dense array of voxel centres (swap-with-last removal) plus key -> index.
  // Per-axis histograms of voxel keys give the map's exact extent without scanning all voxels.
  const voxels = {
    count: 0,
    keys: new Float64Array(voxelBuffer.capacity),
    indexByKey: new Map(),
    keyHistograms: [new Uint32Array(65536), new Uint32Array(65536), new Uint32Array(65536)],
    rampMinHeight_m: 0,
    rampMaxHeight_m: 1,
    dirty: false,
  };

  // Trail vertices occupy [trail.start, trail.start + trail.count) of trailBuffer.
  const trail = { start: 0, count: 0, newestPose: null, newestChanged: false };
  let keyframeCount = 0;
  let statusMessage = null;
  let statusReceivedAt_ms = 0;

  const fullState = { pending: false, applied: false, helloAt_ms: 0, sawReplace: false, sawTrail: false };
  let firstPaint_ms = null;
  let hasFramedView = false;
  let needsRender = true;
  let occupancyDirty = true;
  let lastOccupancyDraw_ms = -Infinity;
  let lastRender_ms = -Infinity;

  // Totals since load; window* = the current one-second statistics window; renderFps and last* =
  // the last completed window (reported in client_stats).
  const counters = {
    framesRendered: 0, messagesReceived: 0, voxelMessages: 0, malformedMessages: 0,
    lastMessage_ms: null, lastVoxelMessage_ms: null, voxelIntervalSum_ms: 0, voxelIntervalCount: 0,
    lastResyncRequest_ms: -Infinity,
    windowStart_ms: performance.now(), windowFrames: 0, windowMaxMessageGap_ms: 0, windowMaxRender_ms: 0,
    renderFps: 0, lastMaxMessageGap_ms: 0, lastMaxRender_ms: 0,
  };

  // ---------------------------------------------------------------------------------------------
  // Voxels
  function setResolution(resolution_m) {
    world.resolution_m = resolution_m;
    // PointsMaterial sizes points as size * (viewport height / 2) / depth pixels; dividing by
    // tan(fov / 2) makes a point resolution_m world units tall (times the overlap factor).
    voxelMaterial.size = VOXEL_POINT_OVERLAP * resolution_m / Math.tan(VIEW_FOV_DEG * Math.PI / 360);
  }

  function clearVoxels() {
    voxels.count = 0;
    voxels.indexByKey.clear();
    for (const histogram of voxels.keyHistograms) histogram.fill(0);
    voxels.dirty = true;
  }

  function addVoxel(key, kx, ky, kz) {
    if (voxels.indexByKey.has(key)) return;
    const index = voxels.count;
    if (index + 1 > voxelBuffer.capacity) {
      voxelBuffer.ensureCapacity(index + 1, index);
      const keys = new Float64Array(voxelBuffer.capacity);
      keys.set(voxels.keys.subarray(0, index));
      voxels.keys = keys;
    }
    const resolution_m = world.resolution_m;
    const positions = voxelBuffer.positions;
    const o = index * 3;
    positions[o] = (kx - VOXEL_KEY_OFFSET + 0.5) * resolution_m;
    positions[o + 1] = (ky - VOXEL_KEY_OFFSET + 0.5) * resolution_m;
    positions[o + 2] = (kz - VOXEL_KEY_OFFSET + 0.5) * resolution_m;
    const height_m = positions[o + world.up.heightAxis] * world.up.heightSign;
    const rampSpan_m = voxels.rampMaxHeight_m - voxels.rampMinHeight_m || 1;
    writeRampColour((height_m - voxels.rampMinHeight_m) / rampSpan_m, voxelBuffer.colours, o);
    voxels.keys[index] = key;
    voxels.indexByKey.set(key, index);
    voxels.keyHistograms[0][kx]++;
    voxels.keyHistograms[1][ky]++;
    voxels.keyHistograms[2][kz]++;
    voxels.count = index + 1;
  }

  function removeVoxel(key, kx, ky, kz) {
    const index = voxels.indexByKey.get(key);
    if (index === undefined) return;
    const last = voxels.count - 1;
    if (index !== last) {
      voxelBuffer.positions.copyWithin(index * 3, last * 3, last * 3 + 3);
      voxelBuffer.colours.copyWithin(index * 3, last * 3, last * 3 + 3);
      const movedKey = voxels.keys[last];
      voxels.keys[index] = movedKey;
      voxels.indexByKey.set(movedKey, index);
    }
    voxels.indexByKey.delete(key);
    voxels.keyHistograms[0][kx]--;
    voxels.keyHistograms[1][ky]--;
    voxels.keyHistograms[2][kz]--;
    voxels.count = last;
  }

  // World-frame extent of the occupied voxel centres along one world axis, or null if empty.
  function voxelAxisRange_m(axis) {
    const histogram = voxels.keyHistograms[axis];
    let lo = 0;
    while (lo < 65536 && histogram[lo] === 0) lo++;
    if (lo === 65536) return null;
    let hi = 65535;
    while (histogram[hi] === 0) hi--;
    const r = world.resolution_m;
    return { min: (lo - VOXEL_KEY_OFFSET + 0.5) * r, max: (hi - VOXEL_KEY_OFFSET + 0.5) * r };
  }

  function signedRange(range, sign) {
    return sign > 0 ? range : { min: -range.max, max: -range.min };
  }

  // Map extent in display coordinates (x, y = height, z), or null if there are no voxels.
  function voxelDisplayBounds() {
    const x = voxelAxisRange_m(0);
    if (!x) return null;
    return {
      x,
      y: signedRange(voxelAxisRange_m(world.up.heightAxis), world.up.heightSign),
      z: signedRange(voxelAxisRange_m(world.up.depthAxis), world.up.depthSign),
    };
  }

  // Recolours all voxels if the height range moved by more than 5 % of its span (or a voxel).
  function updateHeightRamp(bounds) {
    if (!bounds) return false;
    const span_m = bounds.y.max - bounds.y.min;
    const tolerance_m = Math.max(0.05 * span_m, world.resolution_m);
    if (Math.abs(bounds.y.min - voxels.rampMinHeight_m) <= tolerance_m &&
        Math.abs(bounds.y.max - voxels.rampMaxHeight_m) <= tolerance_m) return false;
    voxels.rampMinHeight_m = bounds.y.min;
    voxels.rampMaxHeight_m = bounds.y.max;
    const rampSpan_m = span_m || 1;
    const positions = voxelBuffer.positions;
    const colours = voxelBuffer.colours;
    const axis = world.up.heightAxis;
    const sign = world.up.heightSign;
    for (let o = 0, end = voxels.count * 3; o < end; o += 3) {
      writeRampColour((positions[o + axis] * sign - bounds.y.min) / rampSpan_m, colours, o);
    }
    return true;
  }

  // Ground grid: 1 m cells under the map at its floor height, rebuilt only when its extent changes.
  function updateGroundGrid(bounds) {
    let centreX = 0;
    let centreZ = 0;
    let size_m = 10;
    if (bounds) {
      centreX = Math.round((bounds.x.min + bounds.x.max) / 2);
      centreZ = Math.round((bounds.z.min + bounds.z.max) / 2);
      const extent_m = Math.max(bounds.x.max - bounds.x.min, bounds.z.max - bounds.z.min);
      size_m = Math.max(10, 2 * Math.ceil(extent_m / 2 + 1));
    }
    const floor_m = bounds ? bounds.y.min - world.resolution_m / 2 : 0;
    if (!groundGrid || groundGrid.userData.size_m !== size_m) {
      if (groundGrid) {
        scene.remove(groundGrid);
        groundGrid.geometry.dispose();
        groundGrid.material.dispose();
      }
      groundGrid = new THREE.GridHelper(size_m, size_m, 0x4a5562, 0x2a313a);
      groundGrid.userData.size_m = size_m;
      scene.add(groundGrid);
    }
    groundGrid.position.set(centreX, floor_m, centreZ);
  }

  // ---------------------------------------------------------------------------------------------
  // Trail and newest camera
  function clearTrail() {
    trail.start = 0;
    trail.count = 0;
    trail.newestPose = null;
    trail.newestChanged = true;
    trailBuffer.geometry.setDrawRange(0, 0);
    newestCameraGroup.visible = false;
  }

  function appendPose(pose) {
    if (!pose || !Array.isArray(pose.p) || !Array.isArray(pose.q)) return;
    if (trail.count === MAX_TRAIL_POSES) {
      trail.start++;
      trail.count--;
    }
    if (trail.start + trail.count + 1 > trailBuffer.capacity) {
      if (trail.start > 0) {
        // Compact: move the kept poses to the front (happens once per ~capacity - MAX poses).
        const from = trail.start * 3;
        const to = (trail.start + trail.count) * 3;
        trailBuffer.positions.copyWithin(0, from, to);
        trailBuffer.colours.copyWithin(0, from, to);
        trail.start = 0;
        trailBuffer.markDirty(0, trail.count);
      }
      trailBuffer.ensureCapacity(trail.count + 1, trail.count);
    }
    const index = trail.start + trail.count;
    trailBuffer.positions.set(pose.p, index * 3);
    stateColour(pose.state).toArray(trailBuffer.colours, index * 3);
    trailBuffer.markDirty(index, index + 1);
    trail.count++;
    trail.newestPose = pose;
    trail.newestChanged = true;
  }

  function appendPoses(poses) {
    if (!Array.isArray(poses)) return;
    const first = Math.max(0, poses.length - MAX_TRAIL_POSES);
    for (let i = first; i < poses.length; i++) appendPose(poses[i]);
    trailBuffer.geometry.setDrawRange(trail.start, trail.count);
    const newest = trail.newestPose;
    if (newest) {
      newestCameraGroup.visible = true;
      newestCameraGroup.position.fromArray(newest.p);
      quaternionFromWxyz(newest.q, newestCameraGroup.quaternion);
      frustumMaterial.color.copy(stateColour(newest.state));
      cameraDotMaterial.color.copy(stateColour(newest.state));
    }
    occupancyDirty = true;
  }

  function newestCameraDisplayPosition() {
    if (!trail.newestPose) return null;
    return new THREE.Vector3().fromArray(trail.newestPose.p).applyQuaternion(worldGroup.quaternion);
  }

  // ---------------------------------------------------------------------------------------------
  // Keyframes and vanishing points
  function setKeyframes(list) {
    const keyframes = (Array.isArray(list) ? list : [])
      .filter((kf) => Array.isArray(kf.p) && Array.isArray(kf.q))
      .sort((a, b) => a.id - b.id);
    keyframeFrustaBuffer.ensureCapacity(keyframes.length * KEYFRAME_FRUSTUM_VERTICES, 0);
    keyframePathBuffer.ensureCapacity(keyframes.length, 0);
    const vertex = new THREE.Vector3();
    const rotation = new THREE.Quaternion();
    const frustumPositions = keyframeFrustaBuffer.positions;
    keyframes.forEach((kf, k) => {
      quaternionFromWxyz(kf.q, rotation);
      for (let v = 0; v < KEYFRAME_FRUSTUM_VERTICES; v++) {
        vertex.fromArray(KEYFRAME_FRUSTUM, v * 3).applyQuaternion(rotation);
        const o = (k * KEYFRAME_FRUSTUM_VERTICES + v) * 3;
        frustumPositions[o] = vertex.x + kf.p[0];
        frustumPositions[o + 1] = vertex.y + kf.p[1];
        frustumPositions[o + 2] = vertex.z + kf.p[2];
      }
      keyframePathBuffer.positions.set(kf.p, k * 3);
    });
    keyframeFrustaBuffer.markDirty(0, keyframes.length * KEYFRAME_FRUSTUM_VERTICES);
    keyframePathBuffer.markDirty(0, keyframes.length);
    keyframeFrustaBuffer.geometry.setDrawRange(0, keyframes.length * KEYFRAME_FRUSTUM_VERTICES);
    keyframePathBuffer.geometry.setDrawRange(0, keyframes.length);
    keyframeCount = keyframes.length;
    needsRender = true;
  }

  function setVanishingPoints(directions) {
    const list = (Array.isArray(directions) ? directions : []).filter((d) => Array.isArray(d.direction_camera));
    vanishingPointBuffer.ensureCapacity(list.length * 2, 0);
    const direction = new THREE.Vector3();
    list.forEach((vp, i) => {
      direction.fromArray(vp.direction_camera).normalize().multiplyScalar(VANISHING_POINT_LENGTH_M);
      const o = i * 6;
      vanishingPointBuffer.positions.fill(0, o, o + 3); // starts at the camera centre
      direction.toArray(vanishingPointBuffer.positions, o + 3);
      const colour = vp.accepted ? VP_ACCEPTED_COLOUR : VP_REJECTED_COLOUR;
      colour.toArray(vanishingPointBuffer.colours, o);
      colour.toArray(vanishingPointBuffer.colours, o + 3);
    });
    vanishingPointBuffer.markDirty(0, list.length * 2);
    vanishingPointBuffer.geometry.setDrawRange(0, list.length * 2);
    needsRender = true;
  }

  // ---------------------------------------------------------------------------------------------
  // Message handling
  function noteMessage() {
    const now_ms = performance.now();
    if (counters.lastMessage_ms !== null) {
      counters.windowMaxMessageGap_ms = Math.max(counters.windowMaxMessageGap_ms, now_ms - counters.lastMessage_ms);
    }
    counters.lastMessage_ms = now_ms;
    counters.messagesReceived++;
    return now_ms;
  }

  function clearAll() {
    clearVoxels();
    clearTrail();
    setKeyframes([]);
    setVanishingPoints([]);
    statusMessage = null;
    renderStatus();
    occupancyDirty = true;
    needsRender = true;
  }

  function applyHello(msg) {
    clearAll();
    world.frameId = String(msg.frame_id || 'world');
    world.upAxisName = UP_AXES[msg.up_axis] ? msg.up_axis : '-y';
    world.up = UP_AXES[world.upAxisName];
    worldGroup.rotation.set(world.up.rotationX_rad, 0, 0);
    worldGroup.updateMatrixWorld(true);
    if (typeof msg.resolution_m === 'number' && msg.resolution_m > 0) setResolution(msg.resolution_m);
    $('frame-id').textContent = `${world.frameId} (up ${world.upAxisName})`;
    Object.assign(fullState, { pending: true, applied: false, helloAt_ms: performance.now(), sawReplace: false, sawTrail: false });
    firstPaint_ms = null;
    document.body.dataset.ready = '0';
    counters.lastVoxelMessage_ms = null;
    counters.voxelIntervalSum_ms = 0;
    counters.voxelIntervalCount = 0;
  }

  function markFullStateApplied() {
    fullState.pending = false;
    fullState.applied = true;
    occupancyDirty = true;
    needsRender = true;
  }

  function handleText(msg) {
    noteMessage();
    if (!msg || typeof msg !== 'object') return;
    switch (msg.type) {
      case 'hello': applyHello(msg); break;
      case 'reset': clearAll(); break;
      case 'trail':
        clearTrail();
        appendPoses(msg.poses);
        fullState.sawTrail = true;
        break;
      case 'poses': appendPoses(msg.poses); break;
      case 'keyframes': setKeyframes(msg.keyframes); break;
      case 'vp': setVanishingPoints(msg.directions); break;
      case 'status':
        statusMessage = msg;
        statusReceivedAt_ms = performance.now();
        renderStatus();
        break;
      case 'viewer':
        renderViewerPanel(msg);
        // "viewer" is the last message of the full state that follows a hello.
        if (fullState.pending) markFullStateApplied();
        break;
      default: break;
    }
    updateCounters();
  }

  function requestResync() {
    const now_ms = performance.now();
    if (now_ms - counters.lastResyncRequest_ms < MALFORMED_RESYNC_INTERVAL_MS) return;
    counters.lastResyncRequest_ms = now_ms;
    send({ type: 'request_full' });
  }

  function handleBinary(buffer) {
    const now_ms = noteMessage();
    counters.voxelMessages++;
    if (counters.lastVoxelMessage_ms !== null) {
      counters.voxelIntervalSum_ms += now_ms - counters.lastVoxelMessage_ms;
      counters.voxelIntervalCount++;
    }
    counters.lastVoxelMessage_ms = now_ms;

    const view = buffer instanceof ArrayBuffer && buffer.byteLength >= VOXEL_HEADER_BYTES ? new DataView(buffer) : null;
    const kind = view ? view.getUint32(0, true) : 0;
    const count = view ? view.getUint32(4, true) : 0;
    const resolution_m = view ? view.getFloat32(8, true) : 0;
    const valid = view && (kind === VOXEL_KIND_REPLACE || kind === VOXEL_KIND_CHANGES) && resolution_m > 0 &&
      buffer.byteLength >= VOXEL_HEADER_BYTES + count * VOXEL_RECORD_BYTES &&
      (kind === VOXEL_KIND_REPLACE || Math.abs(resolution_m - world.resolution_m) < 1e-6);
    if (!valid) {
      counters.malformedMessages++;
      requestResync();
      return;
    }
    if (kind === VOXEL_KIND_REPLACE) {
      clearVoxels();
      if (resolution_m !== world.resolution_m) setResolution(resolution_m);
      fullState.sawReplace = true;
    }
    for (let i = 0, o = VOXEL_HEADER_BYTES; i < count; i++, o += VOXEL_RECORD_BYTES) {
      const kx = view.getUint16(o, true);
      const ky = view.getUint16(o + 2, true);
      const kz = view.getUint16(o + 4, true);
      const key = kx + 65536 * (ky + 65536 * kz);
      if (view.getUint16(o + 6, true)) addVoxel(key, kx, ky, kz);
      else removeVoxel(key, kx, ky, kz);
    }
    voxels.dirty = true;
    occupancyDirty = true;
    updateCounters();
  }

  function updateCounters() {
    $('poses-received').textContent = String(trail.count);
    $('voxels-shown').textContent = String(voxels.count);
    $('keyframes-shown').textContent = String(keyframeCount);
  }

  // ---------------------------------------------------------------------------------------------
  // Status and viewer panels
  function renderStatus() {
    const container = $('status-table');
    const s = statusMessage;
    if (!s) {
      container.innerHTML = '<div class="placeholder">no status received</div>';
      updateStatusAge();
      return;
    }
    const stageRows = (Array.isArray(s.stages) ? s.stages : []).map((stage) => `<tr>
      <td>${escapeHtml(stage.name)}</td><td>${formatNumber(stage.rate_hz, 1)}</td>
      <td>${formatNumber(stage.latency_p50_ms, 1)}</td><td>${formatNumber(stage.latency_p95_ms, 1)}</td>
      <td>${formatNumber(stage.latency_p99_ms, 1)}</td><td>${escapeHtml(stage.queue_depth)}/${escapeHtml(stage.queue_capacity)}</td>
      <td class="${stage.drops > 0 ? 'bad' : ''}">${escapeHtml(stage.drops)}</td>
      <td class="${stage.errors > 0 ? 'bad' : ''}">${escapeHtml(stage.errors)}</td></tr>`).join('');
    const summary = [
      ['end-to-end p50/p95/p99 ms',
        `${formatNumber(s.end_to_end_p50_ms, 1)} / ${formatNumber(s.end_to_end_p95_ms, 1)} / ${formatNumber(s.end_to_end_p99_ms, 1)}`],
      ['tracking state', `${s.tracking_state_name} (${s.tracking_state})`],
      ['corridor mode', s.corridor_mode],
      ['map voxels occupied/total', `${s.map_occupied_voxels} / ${s.map_total_voxels}`],
      ['keyframes / loops / relocalisations', `${s.num_keyframes} / ${s.num_loops} / ${s.num_relocalizations}`],
      ['memory', memoryText(s)],
      ['message', s.message || ''],
    ].map(([name, value]) => `<tr><td>${escapeHtml(name)}</td><td>${escapeHtml(value)}</td></tr>`).join('');
    container.innerHTML = `<table class="stages"><thead><tr><th>stage</th><th>Hz</th><th>p50</th><th>p95</th>
      <th>p99</th><th>queue</th><th>drops</th><th>errors</th></tr></thead><tbody>${stageRows}</tbody></table>
      <table class="kv"><tbody>${summary}</tbody></table>`;
    updateStatusAge();
  }

  function updateStatusAge() {
    const ageElement = $('status-age');
    if (!statusMessage) {
      ageElement.textContent = 'no status';
      ageElement.classList.remove('stale');
      return;
    }
    const age_s = (performance.now() - statusReceivedAt_ms) / 1000;
    const stale = age_s > STATUS_STALE_S;
    ageElement.textContent = `${age_s.toFixed(1)} s ago${stale ? ' (stale)' : ''}`;
    ageElement.classList.toggle('stale', stale);
  }

  function renderViewerPanel(msg) {
    const yesNo = (value) => (value ? 'yes' : 'no');
    const rows = [
      ['slamd alive', yesNo(msg.slamd_alive)], ['map synchronised', yesNo(msg.map_synchronised)],
      ['poses received', msg.poses_received], ['voxels', msg.voxels], ['full maps', msg.full_maps],
      ['updates applied', msg.updates_applied], ['gaps', msg.gaps], ['map requests', msg.map_requests],
      ['malformed', msg.malformed], ['clients', msg.clients],
    ].map(([name, value]) => `<td>${escapeHtml(name)}</td><td>${escapeHtml(value === undefined ? '-' : value)}</td>`);
    // Two name/value pairs per table row keeps the panel short.
    let body = '';
    for (let i = 0; i < rows.length; i += 2) body += `<tr>${rows[i]}${rows[i + 1] || ''}</tr>`;
    $('viewer-panel').innerHTML = `<table class="kv kv2"><tbody>${body}</tbody></table>`;
  }

  // ---------------------------------------------------------------------------------------------
  // 2D occupancy view: top-down along the up axis (screen right = display x, screen down = display z).
  const occupancyCanvas = $('occupancy-2d');
  const occupancyCells = { canvas: document.createElement('canvas'), counts: new Uint16Array(0) };

  function niceLength_m(approx_m) {
    const power = Math.pow(10, Math.floor(Math.log10(approx_m)));
    const mantissa = approx_m / power;
    return (mantissa >= 5 ? 5 : mantissa >= 2 ? 2 : 1) * power;
  }

  function drawOccupancy() {
    const cssWidth = occupancyCanvas.clientWidth || 300;
    const cssHeight = occupancyCanvas.clientHeight || 300;
    const pixelRatio = window.devicePixelRatio || 1;
    if (occupancyCanvas.width !== Math.round(cssWidth * pixelRatio)) {
      occupancyCanvas.width = Math.round(cssWidth * pixelRatio);
      occupancyCanvas.height = Math.round(cssHeight * pixelRatio);
    }
    const ctx = occupancyCanvas.getContext('2d');
    ctx.setTransform(pixelRatio, 0, 0, pixelRatio, 0, 0);
    ctx.fillStyle = '#eceae4';
    ctx.fillRect(0, 0, cssWidth, cssHeight);

    const up = world.up;
    const resolution_m = world.resolution_m;
    const trailPositions = trailBuffer.positions;
    const trailStride = Math.max(1, Math.ceil(trail.count / 4000));
    // Extent: map voxels plus the trail.
    const bounds = voxelDisplayBounds();
    let uMin = bounds ? bounds.x.min - resolution_m / 2 : Infinity;
    let uMax = bounds ? bounds.x.max + resolution_m / 2 : -Infinity;
    let vMin = bounds ? bounds.z.min - resolution_m / 2 : Infinity;
    let vMax = bounds ? bounds.z.max + resolution_m / 2 : -Infinity;
    for (let i = trail.start; i < trail.start + trail.count; i++) {
      const u = trailPositions[i * 3];
      const v = trailPositions[i * 3 + up.depthAxis] * up.depthSign;
      uMin = Math.min(uMin, u); uMax = Math.max(uMax, u);
      vMin = Math.min(vMin, v); vMax = Math.max(vMax, v);
    }
    // Snap the origin to the voxel grid so that every cell holds the same number of voxel columns.
    uMin = Math.floor(uMin / resolution_m) * resolution_m;
    vMin = Math.floor(vMin / resolution_m) * resolution_m;
    if (!(uMax >= uMin)) {
      ctx.fillStyle = '#6f6a60';
      ctx.font = '13px sans-serif';
      ctx.fillText('no map yet', 12, 22);
      return;
    }
    const margin_px = 10;
    const scaleBarSpace_px = 24;
    const uSpan_m = Math.max(uMax - uMin, 1);
    const vSpan_m = Math.max(vMax - vMin, 1);
    const pxPerM = Math.min((cssWidth - 2 * margin_px) / uSpan_m, (cssHeight - 2 * margin_px - scaleBarSpace_px) / vSpan_m);
    const originX = (cssWidth - (uMax - uMin) * pxPerM) / 2;
    const originY = margin_px + (cssHeight - 2 * margin_px - scaleBarSpace_px - (vMax - vMin) * pxPerM) / 2;
    const toX = (u) => originX + (u - uMin) * pxPerM;
    const toY = (v) => originY + (v - vMin) * pxPerM;

    if (bounds) {
      // Bin the voxels in the height band into cells of a whole number of voxels, >= one canvas pixel.
      const cellSize_m = resolution_m * Math.max(1, Math.ceil(1 / (pxPerM * pixelRatio * resolution_m)));
      const cellsU = Math.ceil((uMax - uMin) / cellSize_m) + 1;
      const cellsV = Math.ceil((vMax - vMin) / cellSize_m) + 1;
      if (occupancyCells.counts.length < cellsU * cellsV) occupancyCells.counts = new Uint16Array(cellsU * cellsV);
      const counts = occupancyCells.counts;
      counts.fill(0, 0, cellsU * cellsV);
      const floor_m = bounds.y.min;
      const bandMin_m = floor_m + (parseFloat($('band-min-m').value) || 0);
      const bandMax_m = floor_m + (parseFloat($('band-max-m').value) || 0);
      const positions = voxelBuffer.positions;
      for (let o = 0, end = voxels.count * 3; o < end; o += 3) {
        const height_m = positions[o + up.heightAxis] * up.heightSign;
        if (height_m < bandMin_m || height_m > bandMax_m) continue;
        const cu = Math.floor((positions[o] - uMin) / cellSize_m);
        const cv = Math.floor((positions[o + up.depthAxis] * up.depthSign - vMin) / cellSize_m);
        counts[cv * cellsU + cu]++;
      }
      const cellCanvas = occupancyCells.canvas;
      cellCanvas.width = cellsU;
      cellCanvas.height = cellsV;
      const cellCtx = cellCanvas.getContext('2d');
      const image = cellCtx.createImageData(cellsU, cellsV);
      const columnsPerCell = Math.pow(cellSize_m / resolution_m, 2);
      for (let c = 0; c < cellsU * cellsV; c++) {
        if (counts[c] === 0) continue;
        // Darkness saturates as the number of occupied voxels per column grows.
        const darkness = 1 - Math.exp(-counts[c] / columnsPerCell / 3);
        const grey = Math.round(200 * (1 - darkness) + 20 * darkness);
        image.data[c * 4] = grey;
        image.data[c * 4 + 1] = grey;
        image.data[c * 4 + 2] = grey + 6;
        image.data[c * 4 + 3] = 255;
      }
      cellCtx.putImageData(image, 0, 0);
      ctx.imageSmoothingEnabled = false;
      ctx.drawImage(cellCanvas, toX(uMin), toY(vMin), cellsU * cellSize_m * pxPerM, cellsV * cellSize_m * pxPerM);
    }

    if (trail.count > 0) {
      ctx.strokeStyle = '#0a7cc4';
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      for (let i = trail.start; i < trail.start + trail.count; i += trailStride) {
        const x = toX(trailPositions[i * 3]);
        const y = toY(trailPositions[i * 3 + up.depthAxis] * up.depthSign);
        if (i === trail.start) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      }
      const newest = trail.newestPose;
      ctx.lineTo(toX(newest.p[0]), toY(newest.p[up.depthAxis] * up.depthSign));
      ctx.stroke();

      // Camera marker: heading = optical +z axis projected onto the ground plane.
      const heading = new THREE.Vector3(0, 0, 1).applyQuaternion(quaternionFromWxyz(newest.q, new THREE.Quaternion()));
      const headingU = heading.x;
      const headingV = heading.getComponent(up.depthAxis) * up.depthSign;
      const angle = Math.atan2(headingV, headingU);
      ctx.save();
      ctx.translate(toX(newest.p[0]), toY(newest.p[up.depthAxis] * up.depthSign));
      ctx.rotate(angle);
      ctx.beginPath();
      ctx.moveTo(12, 0);
      ctx.lineTo(-6, 7);
      ctx.lineTo(-3, 0);
      ctx.lineTo(-6, -7);
      ctx.closePath();
      ctx.fillStyle = `#${stateColour(newest.state).getHexString()}`;
      ctx.strokeStyle = '#111';
      ctx.lineWidth = 1.2;
      ctx.fill();
      ctx.stroke();
      ctx.restore();
    }

    const barLength_m = niceLength_m((cssWidth * 0.3) / pxPerM);
    const barLength_px = barLength_m * pxPerM;
    const barY = cssHeight - 10;
    ctx.strokeStyle = '#222';
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(10, barY - 4); ctx.lineTo(10, barY); ctx.lineTo(10 + barLength_px, barY); ctx.lineTo(10 + barLength_px, barY - 4);
    ctx.stroke();
    ctx.fillStyle = '#222';
    ctx.font = '11px sans-serif';
    ctx.fillText(`${barLength_m >= 1 ? barLength_m.toFixed(0) : barLength_m} m`, 16 + barLength_px, barY);
  }

  // ---------------------------------------------------------------------------------------------
  // View controls and rendering
  function resetView() {
    const bounds = voxelDisplayBounds();
    const centre = bounds
      ? new THREE.Vector3((bounds.x.min + bounds.x.max) / 2, bounds.y.min, (bounds.z.min + bounds.z.max) / 2)
      : newestCameraDisplayPosition() || new THREE.Vector3();
    const radius_m = bounds
      ? Math.max(2, 0.5 * Math.hypot(bounds.x.max - bounds.x.min, bounds.z.max - bounds.z.min))
      : 3;
    const target = ($('follow-camera').checked && newestCameraDisplayPosition()) || centre;
    controls.target.copy(target);
    camera.position.copy(target).add(new THREE.Vector3(0.4, 1.2, 1.5).multiplyScalar(radius_m));
    controls.update();
    needsRender = true;
  }

  function followNewestCamera() {
    const position = newestCameraDisplayPosition();
    if (!position) return;
    const delta = position.clone().sub(controls.target);
    if (delta.lengthSq() === 0) return;
    camera.position.add(delta);
    controls.target.copy(position);
    controls.update();
  }

  function resize() {
    const width = view3d.clientWidth || 1;
    const height = view3d.clientHeight || 1;
    renderer.setSize(width, height);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
    needsRender = true;
  }

  // Uploads everything that changed since the last frame; returns true if the scene changed.
  function flushChanges() {
    let changed = false;
    if (voxels.dirty) {
      const bounds = voxelDisplayBounds();
      updateHeightRamp(bounds);
      updateGroundGrid(bounds);
      voxelBuffer.markDirty(0, voxels.count);
      voxelBuffer.geometry.setDrawRange(0, voxels.count);
      voxels.dirty = false;
      changed = true;
    }
    for (const buffer of [voxelBuffer, trailBuffer, keyframeFrustaBuffer, keyframePathBuffer, vanishingPointBuffer]) {
      if (buffer.upload()) changed = true;
    }
    if (trail.newestChanged) {
      if ($('follow-camera').checked) followNewestCamera();
      trail.newestChanged = false;
      changed = true;
    }
    return changed;
  }

  function animationFrame() {
    requestAnimationFrame(animationFrame);
    const start_ms = performance.now();
    if (fullState.pending && fullState.sawReplace && fullState.sawTrail &&
        start_ms - fullState.helloAt_ms > FULL_STATE_FALLBACK_MS) {
      markFullStateApplied();
    }
    const newlyApplied = fullState.applied && firstPaint_ms === null;
    if (newlyApplied && !hasFramedView) {
      flushChanges();
      resetView();
      hasFramedView = true;
    }
    const changed = flushChanges();
    if (changed || needsRender || newlyApplied || start_ms - lastRender_ms >= MAX_RENDER_INTERVAL_MS) {
      renderer.render(scene, camera);
      needsRender = false;
      lastRender_ms = start_ms;
      counters.framesRendered++;
      counters.windowFrames++;
    }
    if (occupancyDirty && (newlyApplied || start_ms - lastOccupancyDraw_ms >= OCCUPANCY_REDRAW_INTERVAL_MS)) {
      drawOccupancy();
      occupancyDirty = false;
      lastOccupancyDraw_ms = start_ms;
    }
    if (newlyApplied) {
      firstPaint_ms = start_ms;
      document.body.dataset.ready = '1';
    }
    counters.windowMaxRender_ms = Math.max(counters.windowMaxRender_ms, performance.now() - start_ms);
  }

  // ---------------------------------------------------------------------------------------------
  // Statistics and WebSocket
  let socket = null;
  const useWebSocket = new URLSearchParams(location.search).get('nows') !== '1';

  function send(obj) {
    if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(obj));
  }

  // The fields of the protocol's client_stats message (windowed values are from the last full second).
  function clientStats() {
    return {
      type: 'client_stats',
      first_paint_ms: firstPaint_ms,
      frames_rendered: counters.framesRendered,
      render_fps: counters.renderFps,
      messages_received: counters.messagesReceived,
      voxel_messages: counters.voxelMessages,
      poses_received: trail.count,
      voxels: voxels.count,
      max_message_gap_ms: counters.lastMaxMessageGap_ms,
      mean_voxel_message_interval_ms: counters.voxelIntervalCount > 0
        ? counters.voxelIntervalSum_ms / counters.voxelIntervalCount : 0,
      max_render_ms: counters.lastMaxRender_ms,
    };
  }

  function stats() {
    return Object.assign(clientStats(), {
      keyframes: keyframeCount,
      malformed_messages: counters.malformedMessages,
      connected: $('connection').textContent === 'connected',
      ready: document.body.dataset.ready === '1',
    });
  }

  // Closes the one-second statistics window and sends client_stats.
  function endStatsWindow() {
    const now_ms = performance.now();
    const elapsed_s = Math.max((now_ms - counters.windowStart_ms) / 1000, 1e-3);
    counters.renderFps = counters.windowFrames / elapsed_s;
    // A message gap still open at the end of the window counts as well (a stalled stream).
    const openGap_ms = counters.lastMessage_ms === null ? 0 : now_ms - counters.lastMessage_ms;
    counters.lastMaxMessageGap_ms = Math.max(counters.windowMaxMessageGap_ms, openGap_ms);
    counters.lastMaxRender_ms = counters.windowMaxRender_ms;
    counters.windowFrames = 0;
    counters.windowMaxMessageGap_ms = 0;
    counters.windowMaxRender_ms = 0;
    counters.windowStart_ms = now_ms;
    $('render-fps').textContent = counters.renderFps.toFixed(0);
    send(clientStats());
  }

  function setConnected(connected) {
    const element = $('connection');
    element.textContent = connected ? 'connected' : 'disconnected';
    element.className = connected ? 'connected' : 'disconnected';
  }

  function connect() {
    const protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
    socket = new WebSocket(`${protocol}//${location.host}/ws`);
    socket.binaryType = 'arraybuffer';
    socket.onopen = () => setConnected(true);
    socket.onmessage = (event) => {
      if (typeof event.data !== 'string') {
        handleBinary(event.data);
        return;
      }
      let msg = null;
      try {
        msg = JSON.parse(event.data);
      } catch (error) {
        counters.malformedMessages++;
      }
      handleText(msg);
    };
    socket.onclose = () => {
      setConnected(false);
      socket = null;
      setTimeout(connect, RECONNECT_DELAY_MS);
    };
  }

  // ---------------------------------------------------------------------------------------------
  // Start-up
  setResolution(world.resolution_m);
  worldGroup.rotation.set(world.up.rotationX_rad, 0, 0);
  updateGroundGrid(null);
  clearTrail();
  renderStatus();
  updateCounters();
  controls.addEventListener('change', () => { needsRender = true; });
  $('reset-view').addEventListener('click', resetView);
  $('follow-camera').addEventListener('change', () => { trail.newestChanged = true; });
  for (const id of ['band-min-m', 'band-max-m']) $(id).addEventListener('input', () => { occupancyDirty = true; });
  window.addEventListener('resize', resize);
  resize();
  setInterval(endStatsWindow, 1000);
  setInterval(updateStatusAge, 250);
  requestAnimationFrame(animationFrame);
  if (useWebSocket) connect();

  window.slamdViewer = { handleText, handleBinary, stats };
})();
