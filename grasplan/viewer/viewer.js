/* grasplan viewer: reads the JSON block #grasplan-data (built by grasplan.viewer.build_data) and
 * draws the cell with three.js. All poses are precomputed in Python; this script only decodes
 * base64 arrays, builds meshes and plays back link poses. No network access (see the page's CSP). */
(function () {
  'use strict';
  const statusEl = document.getElementById('render-status');
  const errorEl = document.getElementById('error');

  function fail(msg) {
    statusEl.dataset.ok = '0';
    statusEl.dataset.error = msg;
    errorEl.hidden = false;
    errorEl.textContent = 'grasplan viewer error: ' + msg;
  }
  window.addEventListener('error', (e) => fail(String(e.message || e)));
  window.addEventListener('unhandledrejection', (e) => fail(String((e.reason && e.reason.stack) || e.reason)));

  // arrays arrive as base64 of zlib-deflated little-endian bytes
  async function dec(s, Type) {
    const bin = atob(s);
    const u8 = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) u8[i] = bin.charCodeAt(i);
    if (typeof DecompressionStream === 'undefined') throw new Error('this browser lacks DecompressionStream; use a current Chrome, Firefox or Safari');
    const stream = new Blob([u8]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Type(await new Response(stream).arrayBuffer());
  }
  function esc(s) {
    return String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c]));
  }

  main().catch((e) => fail((e && e.stack) || String(e)));

  async function main() {
    const THREE = window.THREE;
    if (!THREE) throw new Error('three.js is missing from the page');
    const D = JSON.parse(document.getElementById('grasplan-data').textContent);

    // ------------------------------------------------------------------ decode
    const G = D.grasps;
    const n = G.n;
    const [gid, gst, gscore, gpair, pairs, pwidth, popen, mstatus, mpair, tcpP, tcpQ] = await Promise.all([
      dec(G.id, Int32Array), dec(G.status, Uint8Array), dec(G.score, Float32Array), dec(G.pair, Uint32Array),
      dec(G.pairs, Float32Array), dec(G.width, Float32Array), dec(G.opening, Float32Array),
      dec(G.marker_status, Uint8Array), dec(G.marker_pair, Uint32Array), dec(G.tcp_p, Float32Array), dec(G.tcp_q, Int16Array)]);
    const GQ = G.quality || {};
    const qa = {};
    await Promise.all([['gravity_margin', Float32Array], ['epsilon', Float32Array], ['sim_slip_m', Float32Array],
      ['sim_turn_deg', Float32Array], ['contact_area', Float32Array], ['contact_type', Int8Array], ['sim_success', Int8Array]]
      .filter(([k]) => GQ[k]).map(async ([k, T]) => { qa[k] = await dec(GQ[k], T); }));
    const grank = new Int32Array(n);
    for (let i = 0; i < n; i++) { const r = G.rank[String(gid[i])]; grank[i] = r === undefined ? -1 : r; }
    const gwidth = (i) => pwidth[gpair[i]];
    const gopen = (i) => popen[gpair[i]];
    const gcont = (i) => pairs.subarray(gpair[i] * 6, gpair[i] * 6 + 6);
    const statuses = D.statuses;
    const byId = new Map();
    for (let i = 0; i < n; i++) byId.set(gid[i], i);

    // ------------------------------------------------------------------ renderer, camera, lights
    const canvas = document.getElementById('canvas');
    const view = document.getElementById('view');
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0xe8edf2);
    const camera = new THREE.PerspectiveCamera(40, 1, 0.002, 50);
    camera.up.set(0, 0, 1); // world z up
    scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a80, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1.5, -1.0, 3.0);
    scene.add(sun);
    const fill = new THREE.DirectionalLight(0xffffff, 0.5);
    fill.position.set(-2, 1.5, 1);
    scene.add(fill);

    function matFromRowMajor(a) {
      const m = new THREE.Matrix4();
      m.set(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11], a[12], a[13], a[14], a[15]);
      return m;
    }
    function setPose(obj, arr, off) {
      obj.position.set(arr[off], arr[off + 1], arr[off + 2]);
      obj.quaternion.set(arr[off + 3], arr[off + 4], arr[off + 5], arr[off + 6]);
    }
    async function geometryOf(block) {
      const [v, f] = await Promise.all([dec(block.v, Float32Array), dec(block.f, Uint32Array)]);
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(v, 3));
      g.setIndex(new THREE.BufferAttribute(f, 1));
      g.computeVertexNormals();
      g.computeBoundingSphere();
      return g;
    }

    // ------------------------------------------------------------------ part and table
    const partGeom = await geometryOf(D.part);
    const partMat = new THREE.MeshStandardMaterial({
      color: 0xb0b8c4, metalness: 0.1, roughness: 0.6, flatShading: true,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
    });
    const partMesh = new THREE.Mesh(partGeom, partMat);
    matFromRowMajor(D.part.T_world_part).decompose(partMesh.position, partMesh.quaternion, partMesh.scale);
    scene.add(partMesh);
    partMesh.updateMatrixWorld(true);
    const partHome = matFromRowMajor(D.part.T_world_part);
    const placeGhost = new THREE.Mesh(partGeom, new THREE.MeshBasicMaterial({ color: 0x00897b, wireframe: true, transparent: true, opacity: 0.25 }));
    placeGhost.visible = false;
    scene.add(placeGhost);
    function setPartMatrix(M) { M.decompose(partMesh.position, partMesh.quaternion, partMesh.scale); }
    const partBox = new THREE.Box3().setFromObject(partMesh);
    const partCenter = partBox.getCenter(new THREE.Vector3());
    const partSize = Math.max(1e-3, partBox.getSize(new THREE.Vector3()).length());

    const tz = D.cell.table_z || 0;
    const tableSize = D.robot ? 2.0 : Math.max(0.3, partSize * 6);
    const tableCenter = D.robot ? new THREE.Vector3(partCenter.x / 2, partCenter.y / 2, tz) : new THREE.Vector3(partCenter.x, partCenter.y, tz);
    const table = new THREE.Mesh(
      new THREE.BoxGeometry(tableSize, tableSize, 0.02),
      new THREE.MeshStandardMaterial({ color: 0xc9b99a, roughness: 0.9, transparent: true, opacity: 0.85 }));
    table.position.set(tableCenter.x, tableCenter.y, tz - 0.01 - 1e-4);
    scene.add(table);
    const grid = new THREE.GridHelper(tableSize, Math.round(tableSize / (D.robot ? 0.1 : 0.01)), 0x8d7f66, 0xb5a68a);
    grid.rotation.x = Math.PI / 2;
    grid.position.set(tableCenter.x, tableCenter.y, tz + 2e-4);
    scene.add(grid);
    const axes = new THREE.AxesHelper(D.robot ? 0.15 : partSize * 0.5);
    axes.position.set(0, 0, tz + 3e-4);
    scene.add(axes);

    // ------------------------------------------------------------------ obstacles and bin (semi-transparent)
    const obstacles = new THREE.Group();
    const obstacleList = D.cell.obstacles || [];
    const roleOf = new Map((D.cell.roles || []).map((r) => [r.role, r]));
    for (const ob of obstacleList) {
      let geom;
      if (ob.box) geom = new THREE.BoxGeometry(ob.box[0], ob.box[1], ob.box[2]);
      else if (ob.cylinder) { geom = new THREE.CylinderGeometry(ob.cylinder[0], ob.cylinder[0], ob.cylinder[1], 32); geom.rotateX(Math.PI / 2); } // axis = local z
      else if (ob.sphere) geom = new THREE.SphereGeometry(ob.sphere[0], 24, 16);
      else if (ob.mesh) geom = await geometryOf(ob.mesh);
      else continue;
      // colour by role (page.py OBSTACLE_ROLES): red only for a neighbour that blocked the pick
      const role = roleOf.get(ob.role) || roleOf.get('obstacle') || { color: '#ef6c00', edge: '#a84300' };
      const isBin = ob.role === 'bin';
      const mat = new THREE.MeshStandardMaterial({ color: new THREE.Color(role.color), roughness: 0.8, transparent: true,
        opacity: isBin ? 0.45 : 0.35, depthWrite: false, side: THREE.DoubleSide });
      const m = new THREE.Mesh(geom, mat);
      matFromRowMajor(ob.T).decompose(m.position, m.quaternion, m.scale);
      m.userData.name = ob.name;
      const edges = new THREE.LineSegments(new THREE.EdgesGeometry(geom, 30), new THREE.LineBasicMaterial({ color: new THREE.Color(role.edge) }));
      m.add(edges);
      obstacles.add(m);
    }
    scene.add(obstacles);
    statusEl.dataset.obstacles = String(obstacles.children.length);

    // ------------------------------------------------------------------ contact points per status
    const visibleStatus = statuses.map(() => true);
    const points = [];
    const pointSize = n > 5000 ? 4 : 6;
    // one marker per (contact pair, status), so the roll variants of a candidate cost one pair
    statuses.forEach((s, si) => {
      let cnt = 0;
      for (let m = 0; m < mstatus.length; m++) if (mstatus[m] === si) cnt++;
      const pos = new Float32Array(cnt * 6);
      let k = 0;
      for (let m = 0; m < mstatus.length; m++) if (mstatus[m] === si) { pos.set(pairs.subarray(mpair[m] * 6, mpair[m] * 6 + 6), k); k += 6; }
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
      const p = new THREE.Points(g, new THREE.PointsMaterial({ color: s.color, size: pointSize, sizeAttenuation: false }));
      // statuses come in display order: the first (planned / ok) is drawn last, on top
      p.renderOrder = statuses.length - si;
      scene.add(p);
      points.push(p);
    });

    // ------------------------------------------------------------------ gripper
    const GR = D.gripper;
    const gripMeshes = await Promise.all(GR.meshes.map(geometryOf));
    const gripMat = new THREE.MeshStandardMaterial({ color: 0x3d4f6b, metalness: 0.3, roughness: 0.5, transparent: true, opacity: 0.8 });
    const fingerMat = new THREE.MeshStandardMaterial({ color: 0x263238, metalness: 0.3, roughness: 0.5 });
    function shapeObj(sh, mat) {
      const geom = sh.box ? new THREE.BoxGeometry(sh.box[0], sh.box[1], sh.box[2]) : gripMeshes[sh.mesh];
      const m = new THREE.Mesh(geom, mat);
      setPose(m, sh.pose, 0);
      return m;
    }
    const gripper = new THREE.Group();
    GR.body.forEach((sh) => gripper.add(shapeObj(sh, gripMat)));
    const fingers = GR.fingers.map((sh) => { const m = shapeObj(sh, fingerMat); gripper.add(m); return m; });
    gripper.visible = false;
    scene.add(gripper);
    function setOpening(o) {
      const t = GR.max_opening > 0 ? o / GR.max_opening : 0;
      fingers.forEach((m, j) => {
        const a = GR.fingers[j].pose, d = GR.finger_shift[j];
        m.position.set(a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]);
      });
    }
    // selected grasp's contacts: two spheres and the closing axis
    const selGroup = new THREE.Group();
    const r = Math.max(0.0015, Math.min(0.004, partSize * 0.02));
    const selSpheres = [0, 1].map(() => {
      const m = new THREE.Mesh(new THREE.SphereGeometry(r, 16, 12), new THREE.MeshBasicMaterial({ color: 0xff1744 }));
      selGroup.add(m);
      return m;
    });
    const axisGeom = new THREE.BufferGeometry();
    axisGeom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
    const axisLine = new THREE.Line(axisGeom, new THREE.LineBasicMaterial({ color: 0xff1744 }));
    selGroup.add(axisLine);
    selGroup.visible = false;
    scene.add(selGroup);

    // ------------------------------------------------------------------ robot
    const R = D.robot;
    let robot = null, rframes = null, linkObjs = [];
    if (R) {
      rframes = await dec(R.frames, Float32Array);
      const geoms = await Promise.all(R.meshes.map(geometryOf));
      const linkMat = new THREE.MeshStandardMaterial({ color: 0xf2a33a, metalness: 0.15, roughness: 0.55, flatShading: true });
      const homeMat = new THREE.MeshStandardMaterial({ color: 0x9aa5b1, transparent: true, opacity: 0.35, depthWrite: false });
      robot = new THREE.Group();
      linkObjs = R.links.map((l) => { const m = new THREE.Mesh(geoms[l.mesh], linkMat); robot.add(m); return m; });
      robot.userData = { linkMat, homeMat };
      scene.add(robot);
    }
    function showFrame(f) {
      const L = R.frame_size;
      for (let l = 0; l < linkObjs.length; l++) setPose(linkObjs[l], rframes, (f * L + l) * 7);
    }
    function tcpOfFrame(f) {
      return (f * R.frame_size + R.frame_size - 1) * 7;
    }
    function robotMaterial(planned) {
      const m = planned ? robot.userData.linkMat : robot.userData.homeMat;
      linkObjs.forEach((o) => { o.material = m; });
    }
    if (R) { showFrame(0); robotMaterial(false); }

    // ------------------------------------------------------------------ camera framing, controls
    const controls = new THREE.OrbitControls(camera, canvas);
    controls.enableDamping = false;
    controls.screenSpacePanning = true;
    // 'part': the part and the gripper around it fill the view; 'all': the whole cell
    function frameView(what) {
      const target = partCenter.clone();
      let dist = Math.max(partSize * 4, 0.6);
      if (what === 'all') {
        if (R) { target.set(partCenter.x * 0.6, partCenter.y * 0.6, tz + 0.3); dist = 1.9; } else dist *= 2;
      }
      controls.target.copy(target);
      camera.position.set(target.x + dist * 0.55, target.y - dist * 0.75, target.z + dist * 0.5);
      camera.near = Math.max(dist / 500, 1e-4);
      camera.far = dist * 60;
      camera.updateProjectionMatrix();
      controls.update();
      requestRender();
    }

    // ------------------------------------------------------------------ rendering on demand
    let pending = false, first = true;
    function render() {
      pending = false;
      renderer.render(scene, camera);
      if (first) {
        first = false;
        statusEl.dataset.ok = '1';
        statusEl.dataset.triangles = String(renderer.info.render.triangles);
        statusEl.dataset.calls = String(renderer.info.render.calls);
        statusEl.dataset.grasps = String(n);
        statusEl.dataset.listed = String(document.querySelectorAll('#grasp-list [data-grasp-id]').length);
        statusEl.dataset.selected = selected < 0 ? '' : String(gid[selected]);
      }
    }
    function requestRender() {
      if (!pending) { pending = true; requestAnimationFrame(render); }
    }
    controls.addEventListener('change', requestRender);
    function resize() {
      const w = Math.max(1, view.clientWidth), h = Math.max(1, view.clientHeight);
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      requestRender();
    }
    window.addEventListener('resize', resize);

    // ------------------------------------------------------------------ header, legend, list
    const counts = D.counts;
    const planned = counts.planned || 0;
    document.getElementById('title').textContent = D.title;
    document.getElementById('summary').textContent =
      `${D.schema} · ${D.part.nf} triangles (file scale ${D.part.scale_to_m} m/unit) · ${n} grasps` +
      ` · gripper ${D.gripper.name} · cell ${D.cell.name}` + (obstacleList.length ? ` (${obstacleList.length} obstacles${D.cell.bin ? ', bin' : ''})` : '') +
      (R ? ` · ${planned} planned · robot ${R.name}` : '') +
      (D.notes && D.notes.length ? `\n${D.notes.join('\n')}` : '');
    const legend = document.getElementById('legend');
    statuses.forEach((s, si) => {
      const lab = document.createElement('label');
      lab.innerHTML = `<input type="checkbox" checked data-status="${esc(s.name)}"><span class="sw" style="background:${s.color}"></span>${esc(s.name)} (${counts[s.name]})`;
      lab.querySelector('input').addEventListener('change', (e) => {
        visibleStatus[si] = e.target.checked;
        points[si].visible = e.target.checked;
        groups[si].el.hidden = !e.target.checked;
        requestRender();
      });
      legend.appendChild(lab);
    });

    // what the semi-transparent bodies are: one swatch per obstacle role present
    const bodies = document.getElementById('bodies');
    for (const r of D.cell.roles || []) {
      const lab = document.createElement('span');
      lab.dataset.role = r.role;
      lab.innerHTML = `<span class="sw sq" style="background:${esc(r.color)}"></span>${esc(r.label)} (${r.n})`;
      bodies.appendChild(lab);
    }
    document.getElementById('bodies-box').hidden = !(D.cell.roles || []).length;

    // groups: planned by rank, the rest by score (best first), then id
    const order = statuses.map(() => []);
    for (let i = 0; i < n; i++) order[gst[i]].push(i);
    const key = (i) => (grank[i] >= 0 ? grank[i] : 1e9);
    order.forEach((arr) => arr.sort((a, b) => key(a) - key(b) || (isNaN(gscore[b]) ? -1 : isNaN(gscore[a]) ? 1 : gscore[b] - gscore[a]) || gid[a] - gid[b]));
    const firstOf = new Map(); // status * pairs.length + pair -> best grasp with that pair and status
    order.forEach((arr, si) => arr.forEach((i) => { const k = si * pairs.length + gpair[i]; if (!firstOf.has(k)) firstOf.set(k, i); }));
    const list = document.getElementById('grasp-list');
    const FULL = D.list_full; // statuses listed in full (the usable grasps); the others in chunks
    const rows = new Map(); // grasp index -> element
    const groups = statuses.map((s, si) => {
      const el = document.createElement('div');
      el.className = 'group';
      el.dataset.status = s.name;
      el.innerHTML = `<div class="group-title"><span class="sw" style="background:${s.color}"></span>${esc(s.name)} <small>${order[si].length}</small></div>`;
      const body = document.createElement('div');
      el.appendChild(body);
      const more = document.createElement('button');
      more.type = 'button';
      more.className = 'more';
      el.appendChild(more);
      list.appendChild(el);
      const grp = { el, body, more, shown: 0, si };
      more.addEventListener('click', () => showMore(grp, D.list_chunk));
      showMore(grp, FULL.includes(s.name) ? order[si].length : D.list_chunk);
      return grp;
    });
    function fmtScore(v) { return isNaN(v) ? '–' : v.toFixed(3); }
    function showMore(grp, k) {
      const arr = order[grp.si];
      const end = Math.min(arr.length, grp.shown + k);
      const frag = document.createDocumentFragment();
      const s = statuses[grp.si];
      for (let j = grp.shown; j < end; j++) {
        const i = arr[j];
        const row = document.createElement('div');
        row.className = 'grasp';
        row.setAttribute('role', 'option');
        row.dataset.graspId = String(gid[i]);
        row.dataset.status = s.name;
        row.innerHTML = `<span class="sw" style="background:${s.color}"></span><span>#${gid[i]}</span><span>${esc(s.name)}</span>` +
          `<span class="w">${(gwidth(i) * 1000).toFixed(1)} mm</span><span class="s">${fmtScore(gscore[i])}</span>`;
        rows.set(i, row);
        frag.appendChild(row);
      }
      grp.body.appendChild(frag);
      grp.shown = end;
      const left = arr.length - end;
      grp.more.hidden = left <= 0;
      grp.more.textContent = `show ${Math.min(left, D.list_chunk)} more (${left} left)`;
    }
    function ensureRow(i) {
      if (rows.has(i)) return rows.get(i);
      const grp = groups[gst[i]];
      const pos = order[grp.si].indexOf(i);
      showMore(grp, pos + 1 - grp.shown);
      return rows.get(i);
    }
    document.getElementById('list-count').textContent = `(${n}; list: id, status, width, score)`;
    list.addEventListener('click', (e) => {
      const row = e.target.closest('[data-grasp-id]');
      if (row) select(byId.get(Number(row.dataset.graspId)));
    });

    // ------------------------------------------------------------------ selection and playback
    let selected = -1, playing = false, playPos = 0, playFrom = 0, playT0 = 0;
    const playBtn = document.getElementById('play');
    const scrub = document.getElementById('scrub');
    const phase = document.getElementById('phase');
    const showRobot = document.getElementById('show-robot');
    const showGripper = document.getElementById('show-gripper');
    const showPart = document.getElementById('show-part');
    if (!R) { showRobot.disabled = true; showRobot.checked = false; }
    showRobot.addEventListener('change', () => { if (robot) robot.visible = showRobot.checked; requestRender(); });
    showGripper.addEventListener('change', () => { gripper.visible = showGripper.checked && selected >= 0; requestRender(); });
    showPart.addEventListener('change', () => { partMesh.visible = showPart.checked; requestRender(); });

    function pathOf(i) { return R && i >= 0 ? R.paths[String(gid[i])] : undefined; }
    // a pick(-and-place) path: the segment a sample belongs to (a boundary sample: the segment it ends)
    function segmentAt(P, k) {
      const S = P.segments || [];
      for (let j = 0; j < S.length; j++) if (k <= S[j].end) return S[j];
      return S[S.length - 1];
    }
    const tcpM = new THREE.Matrix4(), tcpPos = new THREE.Vector3(), tcpQuat = new THREE.Quaternion(), unit = new THREE.Vector3(1, 1, 1);
    // the part: at its pick pose until the close, TCP @ T_tcp_part while attached, at the place after the release
    function partState(P, k) {
      if (!P.attached || k < P.attached[0]) return 'static';
      if (P.attached[1] === null || k <= P.attached[1]) return 'attached';
      return 'placed';
    }
    function placePart(P, k) {
      const st = partState(P, k);
      if (st === 'attached') {
        const o = tcpOfFrame(P.start + k);
        tcpPos.set(rframes[o], rframes[o + 1], rframes[o + 2]);
        tcpQuat.set(rframes[o + 3], rframes[o + 4], rframes[o + 5], rframes[o + 6]).normalize();
        tcpM.compose(tcpPos, tcpQuat, unit).multiply(matFromRowMajor(P.T_tcp_part));
        setPartMatrix(tcpM);
      } else if (st === 'placed' && P.T_world_part_place) setPartMatrix(matFromRowMajor(P.T_world_part_place));
      else setPartMatrix(partHome);
      return st;
    }
    function setSample(k) {
      const P = pathOf(selected);
      if (!P) return;
      k = Math.max(0, Math.min(P.count - 1, k));
      const f = P.start + k;
      showFrame(f);
      setPose(gripper, rframes, tcpOfFrame(f));
      scrub.value = String(k);
      let opening = P.opening;
      let event = '';
      (P.events || []).forEach((e) => { if (k >= e.sample) opening = e.width; if (k === e.sample) event = e.action; });
      setOpening(opening);
      const st = placePart(P, k);
      const seg = segmentAt(P, k);
      if ((P.segments || []).length > 2) {
        phase.textContent = k === 0 ? 'home' : seg.label + (event ? ' · ' + event : '');
      } else {
        phase.textContent = k === 0 ? 'home' : k === P.count - 1 ? 'grasp' : (P.pregrasp !== null && k < P.pregrasp ? 'to pre-grasp' : (P.pregrasp !== null && k === P.pregrasp ? 'pre-grasp' : 'approach'));
      }
      statusEl.dataset.phase = seg ? seg.label : '';
      statusEl.dataset.part = st;
      timeline.querySelectorAll('[data-segment]').forEach((el) => el.classList.toggle('cur', seg !== undefined && el.dataset.segment === seg.label));
      requestRender();
    }
    // the timeline under the slider: one labelled block per segment, ticks at the gripper events
    const timeline = document.getElementById('timeline');
    function buildTimeline(P) {
      timeline.textContent = '';
      if (!P || !P.segments) { timeline.hidden = true; statusEl.dataset.segments = ''; return; }
      timeline.hidden = false;
      const span = Math.max(1, P.count - 1);
      P.segments.forEach((sg) => {
        const el = document.createElement('span');
        el.className = 'seg';
        el.dataset.segment = sg.label;
        el.style.flexGrow = String(Math.max(1, sg.end - sg.start));
        el.textContent = sg.label;
        el.title = `${sg.label}: samples ${sg.start}-${sg.end}`;
        el.addEventListener('click', () => { playing = false; setSample(sg.start); });
        timeline.appendChild(el);
      });
      (P.events || []).forEach((e) => {
        const t = document.createElement('span');
        t.className = 'ev ev-' + e.action;
        t.dataset.event = e.action;
        t.style.left = (100 * e.sample / span) + '%';
        t.title = `${e.action} to ${(e.width * 1000).toFixed(1)} mm`;
        timeline.appendChild(t);
      });
      statusEl.dataset.segments = P.segments.map((sg) => sg.label).join(',');
    }
    function qualityText(i) {
      const lines = [];
      const num = (a) => (a && !isNaN(a[i]) ? a[i] : null);
      const gm = num(qa.gravity_margin), ep = num(qa.epsilon);
      if (gm !== null || ep !== null) {
        lines.push(`quality: score ${fmtScore(gscore[i])}` + (gm !== null ? `  gravity margin ${gm.toFixed(2)}` : '') +
          (ep !== null ? `  epsilon ${ep.toFixed(4)}` : ''));
      }
      if (qa.contact_type && qa.contact_type[2 * i] >= 0) {
        const names = GQ.contact_types || [];
        const c = [0, 1].map((j) => `${esc(names[qa.contact_type[2 * i + j]] || '?')} ${(qa.contact_area[2 * i + j] * 1e6).toFixed(1)} mm\u00b2`);
        lines.push(`contacts: ${c.join(', ')}`);
      }
      if (qa.sim_success && qa.sim_success[i] >= 0) {
        lines.push(`sim: ${qa.sim_success[i] ? 'held' : 'slipped'}` +
          (num(qa.sim_slip_m) !== null ? `  slip ${(qa.sim_slip_m[i] * 1000).toFixed(1)} mm` : '') +
          (num(qa.sim_turn_deg) !== null ? `  turn ${qa.sim_turn_deg[i].toFixed(1)}\u00b0` : ''));
      }
      return lines.length ? '\n' + lines.join('\n') : '';
    }
    function select(i) {
      if (i === undefined || i < 0 || i >= n) return;
      if (selected >= 0 && rows.has(selected)) rows.get(selected).classList.remove('sel');
      selected = i;
      playing = false;
      playBtn.textContent = '\u25B6 Play path';
      const row = ensureRow(i);
      if (row) { row.classList.add('sel'); row.scrollIntoView({ block: 'nearest' }); }
      const s = statuses[gst[i]].name;
      gripper.position.set(tcpP[i * 3], tcpP[i * 3 + 1], tcpP[i * 3 + 2]);
      gripper.quaternion.set(tcpQ[i * 4], tcpQ[i * 4 + 1], tcpQ[i * 4 + 2], tcpQ[i * 4 + 3]).normalize();
      setOpening(gopen(i));
      gripper.visible = showGripper.checked;
      const c = gcont(i);
      selSpheres[0].position.set(c[0], c[1], c[2]);
      selSpheres[1].position.set(c[3], c[4], c[5]);
      axisGeom.attributes.position.array.set(c);
      axisGeom.attributes.position.needsUpdate = true;
      axisGeom.computeBoundingSphere();
      selGroup.visible = true;
      const P = pathOf(i);
      let txt = `grasp #${gid[i]}  ${s}\nwidth ${(gwidth(i) * 1000).toFixed(2)} mm   pre-grasp opening ${(gopen(i) * 1000).toFixed(1)} mm\nscore ${fmtScore(gscore[i])}` + (grank[i] >= 0 ? `   rank ${grank[i]}` : '');
      txt += qualityText(i);
      buildTimeline(P);
      setPartMatrix(partHome);
      placeGhost.visible = false;
      if (P) {
        robotMaterial(true);
        scrub.max = String(P.count - 1);
        scrub.disabled = false;
        playBtn.disabled = false;
        const appr = (P.segments || []).find((sg) => sg.label === 'approach');
        setSample(appr ? appr.end : P.count - 1); // robot at q_grasp
        txt += `\npath: ${P.waypoints} waypoints, ${P.count} samples`;
        if (P.segments && P.segments.length > 2) txt += `\nsequence: ${P.segments.map((sg) => sg.label).join(' \u2192 ')}`;
        if (P.T_world_part_place) {
          matFromRowMajor(P.T_world_part_place).decompose(placeGhost.position, placeGhost.quaternion, placeGhost.scale);
          placeGhost.visible = true;
        }
      } else {
        if (R) { robotMaterial(false); showFrame(0); }
        scrub.disabled = true;
        playBtn.disabled = true;
        phase.textContent = R ? 'robot at home' : '';
      }
      document.getElementById('selected').textContent = txt;
      statusEl.dataset.selected = String(gid[i]);
      requestRender();
    }
    // playback is driven by the clock (60 samples per second, about 1.8 rad/s at the densified
    // step), so a throttled or slow frame rate skips samples instead of slowing the motion down
    function tick() {
      if (!playing) return;
      const P = pathOf(selected);
      playPos = playFrom + (performance.now() - playT0) / 1000 * 60;
      if (playPos >= P.count - 1) {
        playPos = P.count - 1;
        playing = false;
        playBtn.textContent = '\u25B6 Play path';
      }
      setSample(Math.floor(playPos));
      statusEl.dataset.played = String(Math.floor(playPos) + 1);
      if (playing) setTimeout(tick, 16); // timers, not frames: also runs under headless virtual time
    }
    playBtn.addEventListener('click', () => {
      const P = pathOf(selected);
      if (!P) return;
      if (playing) { playing = false; playBtn.textContent = '\u25B6 Play path'; return; }
      playFrom = Number(scrub.value) >= P.count - 1 ? 0 : Number(scrub.value);
      playT0 = performance.now();
      playing = true;
      playBtn.textContent = '\u275A\u275A Pause';
      setTimeout(tick, 0);
    });
    scrub.addEventListener('input', () => { playing = false; setSample(Number(scrub.value)); });

    // keyboard: up/down through the rendered rows
    window.addEventListener('keydown', (e) => {
      if (e.key !== 'ArrowDown' && e.key !== 'ArrowUp') return;
      const vis = Array.from(list.querySelectorAll('.group:not([hidden]) [data-grasp-id]'));
      if (!vis.length) return;
      const cur = selected >= 0 ? vis.indexOf(rows.get(selected)) : -1;
      const nxt = vis[Math.max(0, Math.min(vis.length - 1, cur + (e.key === 'ArrowDown' ? 1 : -1)))];
      select(byId.get(Number(nxt.dataset.graspId)));
      e.preventDefault();
    });
    // click in the 3D view on a contact point (nearest visible one within 10 px) selects its grasp
    let down = null;
    canvas.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
    canvas.addEventListener('pointerup', (e) => {
      if (!down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 4) return;
      const rect = canvas.getBoundingClientRect();
      const x = e.clientX - rect.left, y = e.clientY - rect.top;
      const v = new THREE.Vector3();
      let best = -1, bd = 100;
      for (let m = 0; m < mstatus.length; m++) {
        if (!visibleStatus[mstatus[m]]) continue;
        const o = mpair[m] * 6;
        for (let k = 0; k < 2; k++) {
          v.set(pairs[o + 3 * k], pairs[o + 3 * k + 1], pairs[o + 3 * k + 2]).project(camera);
          if (v.z > 1) continue;
          const dx = (v.x + 1) / 2 * rect.width - x, dy = (1 - v.y) / 2 * rect.height - y;
          const d = dx * dx + dy * dy;
          if (d < bd) { bd = d; best = m; }
        }
      }
      // the marker's best grasp: the first one of its status group (rank, then score order)
      if (best >= 0) select(firstOf.get(mstatus[best] * pairs.length + mpair[best]));
    });
    document.getElementById('hud').textContent = 'drag: orbit · right-drag: pan · wheel: zoom · click a contact point or a list row';

    // ------------------------------------------------------------------ initial state
    resize();
    frameView('part');
    document.getElementById('frame-part').addEventListener('click', () => frameView('part'));
    document.getElementById('frame-all').addEventListener('click', () => frameView('all'));
    let initial = -1;
    for (let si = 0; si < statuses.length && initial < 0; si++) if (order[si].length) initial = order[si][0];
    // the URL fragment can pick a grasp and start the path: view.html#grasp=12&play
    const hash = new URLSearchParams(location.hash.replace(/^#/, ''));
    if (hash.has('grasp') && byId.has(Number(hash.get('grasp')))) initial = byId.get(Number(hash.get('grasp')));
    if (initial >= 0) select(initial);
    render(); // first frame now, so the status element is set even without animation frames
    if (hash.has('sample') && pathOf(selected)) setSample(Number(hash.get('sample')));
    if (hash.has('view')) frameView(hash.get('view'));
    if (hash.has('play')) playBtn.click();
  }
})();
