/* grasplan clutter replay: reads the JSON block #grasplan-data (built by grasplan.clutter.replay.build_data)
 * and plays back each recorded pick with three.js. Poses are precomputed in Python (x, y, z, qx, qy, qz, qw);
 * this script decodes base64 arrays, builds meshes and sets poses. No network access (see the page's CSP). */
(function () {
  'use strict';
  const statusEl = document.getElementById('render-status');
  const errorEl = document.getElementById('error');
  function fail(msg) {
    statusEl.dataset.ok = '0';
    statusEl.dataset.error = msg;
    errorEl.hidden = false;
    errorEl.textContent = 'grasplan replay error: ' + msg;
  }
  window.addEventListener('error', (e) => fail(String(e.message || e)));
  window.addEventListener('unhandledrejection', (e) => fail(String((e.reason && e.reason.stack) || e.reason)));

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
  const pct = (x) => (x === null || x === undefined ? '–' : (100 * x).toFixed(1) + ' %');

  main().catch((e) => fail((e && e.stack) || String(e)));

  async function main() {
    const THREE = window.THREE;
    if (!THREE) throw new Error('three.js is missing from the page');
    const D = JSON.parse(document.getElementById('grasplan-data').textContent);

    // ------------------------------------------------------------------ renderer, camera, lights
    const canvas = document.getElementById('canvas');
    const view = document.getElementById('view');
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0xe8edf2);
    const camera = new THREE.PerspectiveCamera(40, 1, 0.002, 50);
    camera.up.set(0, 0, 1);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a80, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1.5, -1.0, 3.0);
    scene.add(sun);

    function matFromRowMajor(a) {
      const m = new THREE.Matrix4();
      m.set(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11], a[12], a[13], a[14], a[15]);
      return m;
    }
    function setPose(obj, arr, off) {
      obj.position.set(arr[off], arr[off + 1], arr[off + 2]);
      obj.quaternion.set(arr[off + 3], arr[off + 4], arr[off + 5], arr[off + 6]).normalize();
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

    // ------------------------------------------------------------------ table, bin, obstacles
    const tz = D.cell.table_z || 0;
    const bin = D.cell.bin;
    const centre = bin ? new THREE.Vector3(bin.T_world_bin[0][3], bin.T_world_bin[1][3], bin.T_world_bin[2][3]) : new THREE.Vector3(0.45, 0, tz);
    const table = new THREE.Mesh(new THREE.BoxGeometry(0.8, 0.6, 0.02),
      new THREE.MeshStandardMaterial({ color: 0xc9b99a, roughness: 0.9, transparent: true, opacity: 0.85 }));
    table.position.set(centre.x, centre.y, tz - 0.01 - 1e-4);
    scene.add(table);
    for (const ob of D.cell.obstacles || []) {
      let geom;
      if (ob.box) geom = new THREE.BoxGeometry(ob.box[0], ob.box[1], ob.box[2]);
      else if (ob.cylinder) { geom = new THREE.CylinderGeometry(ob.cylinder[0], ob.cylinder[0], ob.cylinder[1], 32); geom.rotateX(Math.PI / 2); }
      else if (ob.sphere) geom = new THREE.SphereGeometry(ob.sphere[0], 24, 16);
      else if (ob.mesh) geom = await geometryOf(ob.mesh);
      else continue;
      const isBin = /^bin_/.test(ob.name);
      const m = new THREE.Mesh(geom, new THREE.MeshStandardMaterial({ color: isBin ? 0x8d6e63 : 0xc62828, roughness: 0.8,
        transparent: true, opacity: isBin ? 0.3 : 0.35, depthWrite: false, side: THREE.DoubleSide }));
      matFromRowMajor(ob.T).decompose(m.position, m.quaternion, m.scale);
      m.add(new THREE.LineSegments(new THREE.EdgesGeometry(geom, 30), new THREE.LineBasicMaterial({ color: isBin ? 0x5d4037 : 0x8e0000 })));
      scene.add(m);
    }

    // ------------------------------------------------------------------ parts (one geometry per part name)
    const geoms = {};
    for (const [name, block] of Object.entries(D.parts)) geoms[name] = await geometryOf(block);
    const partMat = new THREE.MeshStandardMaterial({ color: 0xb0b8c4, metalness: 0.1, roughness: 0.6, flatShading: true });
    const targetMat = new THREE.MeshStandardMaterial({ color: 0xffb74d, metalness: 0.1, roughness: 0.6, flatShading: true });
    const raisedMat = new THREE.MeshStandardMaterial({ color: 0x9575cd, metalness: 0.1, roughness: 0.6, flatShading: true });
    const seenMat = new THREE.MeshBasicMaterial({ color: 0x00897b, wireframe: true, transparent: true, opacity: 0.5 });
    const pileGroup = new THREE.Group();
    scene.add(pileGroup);
    const seenMesh = new THREE.Mesh(new THREE.BufferGeometry(), seenMat);
    seenMesh.visible = false;
    scene.add(seenMesh);

    // ------------------------------------------------------------------ gripper (the viewer's encoding)
    const GR = D.gripper;
    const gripMeshes = await Promise.all(GR.meshes.map(geometryOf));
    const gripMat = new THREE.MeshStandardMaterial({ color: 0x3d4f6b, metalness: 0.3, roughness: 0.5, transparent: true, opacity: 0.8 });
    const fingerMat = new THREE.MeshStandardMaterial({ color: 0x263238, metalness: 0.3, roughness: 0.5 });
    function shapeObj(sh, mat) {
      const m = new THREE.Mesh(sh.box ? new THREE.BoxGeometry(sh.box[0], sh.box[1], sh.box[2]) : gripMeshes[sh.mesh], mat);
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
    const frames = new THREE.Group();
    const frameAxes = [0, 1, 2].map(() => { const a = new THREE.AxesHelper(0.03); frames.add(a); return a; });
    frames.visible = false;
    scene.add(frames);

    // ------------------------------------------------------------------ camera, rendering on demand
    const controls = new THREE.OrbitControls(camera, canvas);
    controls.enableDamping = false;
    controls.screenSpacePanning = true;
    function frameView() {
      controls.target.set(centre.x, centre.y, centre.z + 0.05);
      camera.position.set(centre.x + 0.35, centre.y - 0.5, centre.z + 0.45);
      camera.near = 0.002;
      camera.far = 20;
      camera.updateProjectionMatrix();
      controls.update();
      requestRender();
    }
    let pending = false, first = true;
    function render() {
      pending = false;
      renderer.render(scene, camera);
      if (first) {
        first = false;
        statusEl.dataset.ok = '1';
        statusEl.dataset.triangles = String(renderer.info.render.triangles);
        statusEl.dataset.listed = String(document.querySelectorAll('#round-list [data-attempt]').length);
      }
      statusEl.dataset.selected = sel ? `${sel.r}:${sel.k}` : '';
      statusEl.dataset.meshes = String(pileGroup.children.length);
    }
    function requestRender() { if (!pending) { pending = true; requestAnimationFrame(render); } }
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
    const T = D.total;
    document.getElementById('title').textContent = D.title;
    document.getElementById('summary').textContent =
      `${T.rounds} rounds · ${T.parts} parts · ${T.attempts} attempts · GSR ${pct(T.gsr)} · DR ${pct(T.dr)}` +
      (T.plan_ms && T.plan_ms.median !== null ? ` · planning ${T.plan_ms.median.toFixed(0)} ms median` : '') +
      ` · gripper ${GR.name} · cell ${D.cell.name}` + (D.notes && D.notes.length ? `\n${D.notes.join('\n')}` : '');
    const legend = document.getElementById('legend');
    for (const [name, color] of Object.entries(D.outcomes)) {
      const s = document.createElement('span');
      s.className = 'opt';
      s.innerHTML = `<span class="sw" style="background:${color}"></span> ${esc(name)}`;
      legend.appendChild(s);
    }
    const list = document.getElementById('round-list');
    const rowsInOrder = [];
    D.rounds.forEach((R, ri) => {
      const head = document.createElement('div');
      head.className = 'round-title';
      head.dataset.round = String(R.r);
      head.innerHTML = `round ${R.r + 1} <small>seed ${R.seed} · ${R.successes}/${R.tried} picks held · ` +
        `${R.successes}/${R.parts} removed · ${esc(R.ended)}</small>`;
      list.appendChild(head);
      R.attempts.forEach((A, k) => {
        const row = document.createElement('div');
        const done = A.samples !== undefined;
        row.className = 'pick' + (done ? '' : ' noplan');
        row.setAttribute('role', 'option');
        row.dataset.round = String(R.r);
        row.dataset.attempt = String(k);
        row.dataset.outcome = A.outcome;
        row.title = A.reason;
        row.innerHTML = `<span class="sw" style="background:${D.outcomes[A.outcome] || '#607d8b'}"></span><span>${k + 1}</span>` +
          `<span>${esc(A.instance || '(no pick)')}</span><span>${esc(A.outcome)}</span><span class="ms">${A.plan_ms.toFixed(0)} ms</span>`;
        if (done) { row.addEventListener('click', () => select(ri, k)); rowsInOrder.push([ri, k, row]); }
        list.appendChild(row);
      });
    });
    document.getElementById('list-count').textContent = `(${D.rounds.length}; pick, instance, outcome, planning)`;

    // ------------------------------------------------------------------ selection and playback
    let sel = null, playing = false, t0 = 0, k0 = 0;
    const playBtn = document.getElementById('play');
    const scrub = document.getElementById('scrub');
    const phase = document.getElementById('phase');
    const showFrames = document.getElementById('show-frames');
    const showSeen = document.getElementById('show-seen');
    showFrames.addEventListener('change', () => { frames.visible = showFrames.checked && !!sel; requestRender(); });
    showSeen.addEventListener('change', () => { seenMesh.visible = showSeen.checked && !!sel; requestRender(); });
    document.getElementById('frame-all').addEventListener('click', frameView);

    function pileMeshes(R, ids, target, raised = []) {  // the target orange, the neighbours its lift raises violet
      pileGroup.clear();
      return ids.map((i) => {
        const mat = R.ids[i] === target ? targetMat : raised.includes(R.ids[i]) ? raisedMat : partMat;
        const m = new THREE.Mesh(geoms[R.part_of[i]], mat);
        pileGroup.add(m);
        return m;
      });
    }
    function showPile(R) {  // a round's pile as dropped
      const ms = pileMeshes(R, R.ids.map((_, i) => i), '');
      ms.forEach((m, i) => setPose(m, R.pile, 7 * i));
    }
    async function select(ri, k) {
      const R = D.rounds[ri], A = R.attempts[k];
      if (A.samples === undefined) return;
      stop();
      if (!A.dec) {
        A.dec = A.samples ? await Promise.all([dec(A.t, Float32Array), dec(A.hand, Float32Array), dec(A.opening, Float32Array), dec(A.parts, Float32Array)])
          : [new Float32Array(0), new Float32Array(0), new Float32Array(0), new Float32Array(0)];
      }
      sel = { r: R.r, k, R, A, meshes: pileMeshes(R, A.ids, A.instance, A.pick.raises || []) };
      statusEl.dataset.selected = `${sel.r}:${sel.k}`;  // at once, not on the next frame (a page dump may come first)
      sel.meshes.forEach((m, j) => setPose(m, A.before, 7 * j));
      seenMesh.geometry = geoms[A.part];
      setPose(seenMesh, A.seen, 0);
      seenMesh.visible = showSeen.checked;
      [A.pick.pre, A.pick.tcp, A.pick.lifted].forEach((p, j) => setPose(frameAxes[j], p, 0));
      frames.visible = showFrames.checked;
      gripper.visible = true;
      rowsInOrder.forEach(([, , row]) => row.classList.toggle('sel', row.dataset.round === String(R.r) && row.dataset.attempt === String(k)));
      document.getElementById('selected').textContent =
        `round ${R.r + 1}, ${A.kind === 'push' ? 'push' : 'pick'} ${k + 1}: ${A.instance} (${A.part})\n${A.outcome}: ${A.reason}\n` +
        `planned in ${A.plan_ms.toFixed(1)} ms; pose error ${A.pose_error_mm.toFixed(1)} mm, ${A.pose_error_deg.toFixed(1)} deg` +
        ((A.pick.raises || []).length ? `\nthe lift raises ${A.pick.raises.join(', ')} lying on it (violet)` : '');
      scrub.max = String(Math.max(0, A.samples - 1));
      scrub.disabled = playBtn.disabled = A.samples === 0;
      setSample(0);
    }
    function setSample(k) {
      if (!sel) return;
      const A = sel.A, [t, hand, opening, parts] = A.dec;
      if (!A.samples) { setPose(gripper, A.pick.pre, 0); setOpening(A.pick.opening); requestRender(); return; }
      k = Math.max(0, Math.min(A.samples - 1, k));
      setPose(gripper, hand, 7 * k);
      setOpening(opening[k]);
      const n = A.ids.length;
      sel.meshes.forEach((m, j) => setPose(m, parts, 7 * (k * n + j)));
      scrub.value = String(k);
      phase.textContent = `${t[k].toFixed(2)} s`;
      statusEl.dataset.sample = String(k);
      requestRender();
    }
    function stop() { playing = false; playBtn.innerHTML = '&#9654; Play'; }
    function tick(now) {
      if (!playing || !sel) return;
      const A = sel.A, t = A.dec[0];
      const tt = t[k0] + (now - t0) / 1000;
      let k = k0;
      while (k + 1 < A.samples && t[k + 1] <= tt) k++;
      setSample(k);
      if (k >= A.samples - 1) stop(); else requestAnimationFrame(tick);
    }
    playBtn.addEventListener('click', () => {
      if (playing) { stop(); return; }
      if (!sel) return;
      playing = true;
      playBtn.innerHTML = '&#10073;&#10073; Pause';
      k0 = Number(scrub.value) >= sel.A.samples - 1 ? 0 : Number(scrub.value);
      t0 = performance.now();
      requestAnimationFrame(tick);
    });
    scrub.addEventListener('input', () => { stop(); setSample(Number(scrub.value)); });
    window.addEventListener('keydown', (e) => {
      if (e.key !== 'ArrowDown' && e.key !== 'ArrowUp' || !rowsInOrder.length) return;
      const at = sel ? rowsInOrder.findIndex(([ri, k]) => D.rounds[ri].r === sel.r && k === sel.k) : -1;
      const next = rowsInOrder[Math.max(0, Math.min(rowsInOrder.length - 1, at + (e.key === 'ArrowDown' ? 1 : -1)))];
      select(next[0], next[1]);
      e.preventDefault();
    });

    // ------------------------------------------------------------------ start: the URL fragment may select a pick (#pick=r:k&play)
    resize();
    frameView();
    if (D.rounds.length) showPile(D.rounds[0]);
    const m = /pick=(\d+):(\d+)/.exec(location.hash);
    if (m) {
      const ri = D.rounds.findIndex((R) => R.r === Number(m[1]));
      if (ri >= 0) {
        await select(ri, Number(m[2]));
        if (/play/.test(location.hash) && sel) { const last = sel.A.samples - 1; setSample(last); }
      }
    } else if (rowsInOrder.length) await select(rowsInOrder[0][0], rowsInOrder[0][1]);
    requestRender();
  }
})();
