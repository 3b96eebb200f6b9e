// nonholo view: draws a replay (time slider, play/pause) or a live fleet (WebSocket snapshots).
// Read-only: the page only GETs /data and listens on /live. Every buffer is bounded.
"use strict";
(function () {
  const TOKEN = new URLSearchParams(location.search).get("token") || "";
  const COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                  "#bcbd22", "#17becf"];
  const TRAIL_S = 20;              // seconds of trail behind each robot
  const LIVE_TRAIL = 2000;         // points kept per robot in live mode
  const RECONNECT_MS = 1000, MAX_RECONNECTS = 30;
  const $ = (id) => document.getElementById(id);
  const canvas = $("world"), ctx = canvas.getContext("2d");
  const state = { page: null, mode: "", frame: 0, playing: true, speed: 1, lastTick: 0, view: null,
                  follow: "", live: null, trails: {}, reconnects: 0, t: 0, robots: {}, autofit: true };
  window.nonholoView = state;      // what tests (and curious users) read

  function q(path) { return path + "?token=" + encodeURIComponent(TOKEN); }
  function fmt(v, digits) { return v === null || v === undefined || !isFinite(v) ? "–" : v.toFixed(digits); }
  function color(i) { return COLORS[i % COLORS.length]; }
  const GREEK = { phi: "φ", theta: "θ" };
  function label(name) { return GREEK[name] || name; }
  function unit(name) { return name === "phi" || name === "heading" ? "rad" : "m"; }
  // The errors a link carries: both outputs of an l–φ link, its own separation for an l–l link.
  function linkErrors(link, child, values) {
    const names = child ? child.outputs : ["e1", "e2"], both = [[names[0], values.e1], [names[1], values.e2]];
    if (!child || child.parents.length < 2) return both;
    const j = child.parents.indexOf(link.parent);
    return j >= 0 && j < 2 ? [both[j]] : both;
  }

  async function load() {
    let response;
    try { response = await fetch(q("/data"), { cache: "no-store" }); } catch (e) { return fail("cannot reach the server"); }
    if (!response.ok) return fail("the server answered " + response.status);
    const page = await response.json();
    start(page);
  }
  function fail(message) { $("status").textContent = message; }

  // A live page opened before the fleet started has no robots yet: fetch them again (bounded).
  async function refreshSetup() {
    if (state.refreshing || state.refreshes >= 20) return;
    state.refreshing = true; state.refreshes = (state.refreshes || 0) + 1;
    try {
      const response = await fetch(q("/data"), { cache: "no-store" });
      if (response.ok) {
        const page = await response.json();
        if (page.mode === "live" && page.robots.length) show(page);
      }
    } finally { state.refreshing = false; }
  }

  function show(page) {
    state.page = page; state.mode = page.mode; state.view = null;
    $("title").textContent = page.title || "nonholo";
    const follow = $("follow");
    while (follow.options.length > 1) follow.remove(1);
    page.robots.forEach((r) => follow.add(new Option(r.name, r.name)));
    follow.value = state.follow;
    $("note").textContent = page.reference || !page.robots.length ? "" : "no reference path in this source";
    buildTables();
  }

  function start(page) {
    state.frame = 0; state.trails = {}; state.clock = undefined;
    show(page);
    $("mode").textContent = page.mode; $("mode").className = "badge " + page.mode;
    $("slider").disabled = page.mode !== "replay";
    $("lost-head").textContent = page.mode === "live" ? "in flight" : "lost";
    $("lost-head").title = page.mode === "live" ? "frames sent and not yet received (in flight, or lost)" :
      "frames sent and never received";
    $("slider").max = page.mode === "replay" ? String(page.t.length - 1) : "0";
    $("play").textContent = state.playing ? "pause" : "play";
    if (page.mode === "live") connect();
    document.body.dataset.mode = page.mode;
  }

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    const ws = new WebSocket(scheme + location.host + q("/live"));
    ws.onmessage = (event) => {
      const snap = JSON.parse(event.data);
      state.reconnects = 0;
      if (!state.page.robots.length && Object.keys(snap.robots).length) refreshSetup();
      if (state.playing || !state.live) {
        state.live = snap;
        for (const [name, r] of Object.entries(snap.robots)) {
          const trail = state.trails[name] || (state.trails[name] = []);
          const last = trail[trail.length - 1];
          if (!last || last[0] !== r.x || last[1] !== r.y) trail.push([r.x, r.y]);
          if (trail.length > LIVE_TRAIL) trail.splice(0, trail.length - LIVE_TRAIL);
        }
      }
      if (snap.done) { ws.close(); setTimeout(load, 300); }
    };
    ws.onclose = () => {
      if (state.live && state.live.done) return;
      if (++state.reconnects <= MAX_RECONNECTS) setTimeout(connect, RECONNECT_MS);
      else fail("the live feed is gone");
    };
  }

  // ---------------------------------------------------------------- current state
  function current() {
    const page = state.page, out = { t: 0, robots: {}, links: {} };
    if (!page) return out;
    if (page.mode === "replay") {
      const k = state.frame;
      out.t = page.t[k];
      page.robots.forEach((r) => {
        out.robots[r.name] = { x: r.x[k], y: r.y[k], theta: r.theta[k], v: r.v[k], omega: r.omega[k],
                               e1: r.e1[k], e2: r.e2[k], state: "" };
      });
      for (const [key, link] of Object.entries(page.links)) {
        const child = out.robots[link.child];
        out.links[key] = { e1: child ? child.e1 : null, e2: child ? child.e2 : null, age_s: null, latency_s: null,
                           lost: link.lost === undefined ? null : link.lost };
      }
    } else if (state.live) {
      const snap = state.live;
      out.t = snap.t;
      for (const [name, r] of Object.entries(snap.robots)) out.robots[name] = { ...r, state: snap.states[name] };
      out.links = snap.links;
    }
    return out;
  }

  // ---------------------------------------------------------------- tables
  function buildTables() {
    const links = $("links").tBodies[0], robots = $("robots").tBodies[0];
    links.innerHTML = ""; robots.innerHTML = "";
    const byName = {};
    state.page.robots.forEach((r, i) => { byName[r.name] = r; r.index = i; });
    for (const [key, link] of Object.entries(state.page.links)) {
      const child = byName[link.child] || { outputs: ["e1", "e2"] };
      const row = links.insertRow();
      row.className = "link-row"; row.dataset.link = key;
      row.insertCell().textContent = key.replace("->", " → ");
      ["errors", "age", "latency", "lost"].forEach((c) => { row.insertCell().className = c; });
    }
    state.page.robots.forEach((r, i) => {
      const row = robots.insertRow();
      row.className = "robot-row"; row.dataset.robot = r.name;
      const name = row.insertCell();
      const swatch = document.createElement("span"); swatch.className = "swatch"; swatch.style.background = color(i);
      name.append(swatch, r.name);
      ["x", "y", "theta", "v", "state"].forEach((c) => { row.insertCell().className = c; });
    });
  }

  function updateTables(now) {
    for (const row of $("links").tBodies[0].rows) {
      const key = row.dataset.link, link = now.links[key] || {}, meta = state.page.links[key];
      const child = state.page.robots.find((r) => r.name === meta.child);
      row.cells[1].textContent = linkErrors(meta, child, link)
        .map(([name, value]) => `Δ${label(name)} ${fmt(value, 3)} ${unit(name)}`).join("  ");
      row.cells[2].textContent = fmt(link.age_s, 2);
      row.cells[3].textContent = fmt(link.latency_s, 3);
      const lost = link.lost !== undefined && link.lost !== null ? link.lost : link.in_flight;
      row.cells[4].textContent = lost === null || lost === undefined ? "–" : String(lost);
      row.cells[4].title = link.lost !== undefined && link.lost !== null ? "frames lost" : "frames in flight or lost";
      row.cells[4].classList.toggle("bad", link.lost > 0);
    }
    for (const row of $("robots").tBodies[0].rows) {
      const r = now.robots[row.dataset.robot];
      if (!r) continue;
      row.cells[1].textContent = fmt(r.x, 2); row.cells[2].textContent = fmt(r.y, 2);
      const wrapped = r.theta - 2 * Math.PI * Math.ceil((r.theta - Math.PI) / (2 * Math.PI));
      row.cells[3].textContent = fmt(wrapped, 2); row.cells[4].textContent = fmt(r.v, 2);
      row.cells[5].textContent = r.state || "–";
    }
  }

  // ---------------------------------------------------------------- drawing
  function bounds() {
    const page = state.page; let xs = [], ys = [];
    if (page.reference) { xs = xs.concat(page.reference.x); ys = ys.concat(page.reference.y); }
    if (page.mode === "replay") page.robots.forEach((r) => { xs = xs.concat(r.x); ys = ys.concat(r.y); });
    else {
      if (state.live) Object.values(state.live.robots).forEach((r) => { xs.push(r.x); ys.push(r.y); });
      Object.values(state.trails).forEach((trail) => trail.forEach((p) => { xs.push(p[0]); ys.push(p[1]); }));
    }
    if (!xs.length) return { x0: -5, x1: 5, y0: -5, y1: 5 };
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (const v of xs) { if (v < x0) x0 = v; if (v > x1) x1 = v; }
    for (const v of ys) { if (v < y0) y0 = v; if (v > y1) y1 = v; }
    const pad = 0.08 * Math.max(x1 - x0, y1 - y0, 2);
    return { x0: x0 - pad, x1: x1 + pad, y0: y0 - pad, y1: y1 + pad };
  }
  function fit() {
    const b = bounds();
    const scale = Math.min(canvas.width / (b.x1 - b.x0), canvas.height / (b.y1 - b.y0));
    state.view = { cx: (b.x0 + b.x1) / 2, cy: (b.y0 + b.y1) / 2, scale };
  }
  function toScreen(x, y) {
    const v = state.view;
    return [canvas.width / 2 + (x - v.cx) * v.scale, canvas.height / 2 - (y - v.cy) * v.scale];
  }
  function polyline(xs, ys, from, to, stroke, width, dash) {
    ctx.beginPath(); ctx.strokeStyle = stroke; ctx.lineWidth = width; ctx.setLineDash(dash || []);
    let pen = false;
    for (let i = from; i < to; i++) {
      if (xs[i] === null || ys[i] === null) { pen = false; continue; }   // a diverged sample
      const [sx, sy] = toScreen(xs[i], ys[i]);
      if (pen) ctx.lineTo(sx, sy); else ctx.moveTo(sx, sy);
      pen = true;
    }
    ctx.stroke(); ctx.setLineDash([]);
  }
  function grid() {
    const v = state.view, target = 80 / v.scale;
    const step = Math.pow(10, Math.ceil(Math.log10(target)));
    const spacing = step / 2 >= target ? step / 2 : step;
    const [wx0, wy1] = [v.cx - canvas.width / 2 / v.scale, v.cy + canvas.height / 2 / v.scale];
    const [wx1, wy0] = [v.cx + canvas.width / 2 / v.scale, v.cy - canvas.height / 2 / v.scale];
    ctx.strokeStyle = "#eee"; ctx.lineWidth = 1; ctx.fillStyle = "#999"; ctx.font = "10px sans-serif";
    let lines = 0;
    for (let x = Math.ceil(wx0 / spacing) * spacing; x <= wx1 && lines < 200; x += spacing, lines++) {
      const [sx] = toScreen(x, 0); ctx.beginPath(); ctx.moveTo(sx, 0); ctx.lineTo(sx, canvas.height); ctx.stroke();
      ctx.fillText(+x.toFixed(6) + " m", sx + 2, canvas.height - 4);
    }
    for (let y = Math.ceil(wy0 / spacing) * spacing; y <= wy1 && lines < 400; y += spacing, lines++) {
      const [, sy] = toScreen(0, y); ctx.beginPath(); ctx.moveTo(0, sy); ctx.lineTo(canvas.width, sy); ctx.stroke();
      ctx.fillText(+y.toFixed(6) + " m", 2, sy - 2);
    }
  }
  function robotShape(x, y, theta, fill, name) {
    const [sx, sy] = toScreen(x, y), size = 11;
    ctx.save(); ctx.translate(sx, sy); ctx.rotate(-theta);
    ctx.beginPath(); ctx.moveTo(size, 0); ctx.lineTo(-size * 0.7, size * 0.6); ctx.lineTo(-size * 0.4, 0);
    ctx.lineTo(-size * 0.7, -size * 0.6); ctx.closePath();
    ctx.fillStyle = fill; ctx.fill(); ctx.strokeStyle = "#222"; ctx.lineWidth = 1; ctx.stroke();
    ctx.restore();
    ctx.font = "12px sans-serif"; ctx.lineWidth = 3; ctx.strokeStyle = "rgba(255,255,255,0.85)";
    ctx.strokeText(name, sx + 10, sy - 10); ctx.fillStyle = "#222"; ctx.fillText(name, sx + 10, sy - 10);
  }

  function draw(now) {
    const page = state.page;
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    if (!page) return;
    if (!state.view || (state.autofit && page.mode === "live")) fit();
    if (state.follow && now.robots[state.follow]) {
      state.view.cx = now.robots[state.follow].x; state.view.cy = now.robots[state.follow].y;
    }
    grid();
    if (page.reference) polyline(page.reference.x, page.reference.y, 0, page.reference.x.length, "#999", 1.5, [6, 4]);
    // trails
    if (page.mode === "replay") {
      const k = state.frame, t = page.t[k];
      let from = k; while (from > 0 && t - page.t[from - 1] <= TRAIL_S) from--;
      page.robots.forEach((r, i) => polyline(r.x, r.y, from, k + 1, color(i), 2));
    } else {
      page.robots.forEach((r, i) => {
        const trail = state.trails[r.name] || [];
        polyline(trail.map((p) => p[0]), trail.map((p) => p[1]), 0, trail.length, color(i), 2);
      });
    }
    // links, labelled with their errors
    for (const [key, link] of Object.entries(page.links)) {
      const a = now.robots[link.parent], b = now.robots[link.child], values = now.links[key] || {};
      if (!a || !b) continue;
      const [ax, ay] = toScreen(a.x, a.y), [bx, by] = toScreen(b.x, b.y);
      ctx.beginPath(); ctx.strokeStyle = "#555"; ctx.lineWidth = 1; ctx.setLineDash([3, 3]);
      ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke(); ctx.setLineDash([]);
      const child = page.robots.find((r) => r.name === link.child);
      const long = Math.hypot(bx - ax, by - ay) > 150;   // short links: the panel has their numbers
      if (long && child && values.e1 !== null && values.e1 !== undefined) {
        ctx.fillStyle = "#555"; ctx.font = "10px sans-serif";
        ctx.fillText(linkErrors(link, child, values).map(([n, v]) => `Δ${label(n)} ${fmt(v, 2)}`).join(" "),
                     (ax + bx) / 2 + 4, (ay + by) / 2 + 12);
      }
    }
    page.robots.forEach((r, i) => {
      const p = now.robots[r.name];
      if (p && p.x !== null && p.y !== null) robotShape(p.x, p.y, p.theta, color(i), r.name);
    });
    // scale bar
    const v = state.view, decade = Math.pow(10, Math.floor(Math.log10(150 / v.scale)));
    const meters = [5, 2, 1].map((m) => m * decade).find((m) => m * v.scale <= 150) || decade;
    ctx.fillStyle = "#222"; ctx.fillRect(canvas.width - 20 - meters * v.scale, canvas.height - 18, meters * v.scale, 3);
    ctx.font = "11px sans-serif"; ctx.fillText(meters + " m", canvas.width - 20 - meters * v.scale, canvas.height - 22);
  }

  function tick(stamp) {
    const page = state.page;
    if (page && page.mode === "replay" && state.playing && page.t.length > 1) {
      const dt = state.lastTick ? Math.min((stamp - state.lastTick) / 1000, 0.5) : 0;
      if (state.clock === undefined || state.clock < page.t[state.frame]) state.clock = page.t[state.frame];
      state.clock += dt * state.speed;
      let k = state.frame;
      while (k < page.t.length - 1 && page.t[k + 1] <= state.clock) k++;
      if (k === page.t.length - 1) { state.playing = false; $("play").textContent = "play"; }
      state.frame = k; $("slider").value = String(k);
    }
    state.lastTick = stamp;
    const now = current();
    state.t = now.t; state.robots = now.robots; state.links = now.links;
    $("time").textContent = "t = " + fmt(now.t, 2) + " s" + (page && page.mode === "replay" ?
      " / " + fmt(page.t[page.t.length - 1], 1) + " s" : "");
    draw(now); updateTables(now);
    requestAnimationFrame(tick);
  }

  // ---------------------------------------------------------------- controls
  $("play").onclick = () => {
    const page = state.page;
    if (page && page.mode === "replay" && !state.playing && state.frame >= page.t.length - 1) {
      state.frame = 0; state.clock = page.t[0];
    }
    state.playing = !state.playing; $("play").textContent = state.playing ? "pause" : "play";
  };
  $("slider").oninput = (e) => {
    state.frame = Number(e.target.value);
    state.clock = state.page && state.page.t ? state.page.t[state.frame] : 0;
  };
  $("speed").onchange = (e) => { state.speed = Number(e.target.value); };
  $("follow").onchange = (e) => { state.follow = e.target.value; if (state.follow) state.autofit = false; };
  const zoom = (factor) => { if (state.view) { state.view.scale *= factor; state.autofit = false; } };
  $("zoom-in").onclick = () => zoom(1.25);
  $("zoom-out").onclick = () => zoom(0.8);
  $("fit").onclick = () => { state.follow = ""; $("follow").value = ""; state.autofit = true; fit(); };
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); zoom(e.deltaY < 0 ? 1.1 : 1 / 1.1); },
                          { passive: false });
  let drag = null;
  canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (e) => {
    if (!drag || !state.view) return;
    state.autofit = false;
    state.view.cx -= (e.clientX - drag[0]) / state.view.scale; state.view.cy += (e.clientY - drag[1]) / state.view.scale;
    drag = [e.clientX, e.clientY];
  });
  window.addEventListener("keydown", (e) => {
    if (e.key === " ") { e.preventDefault(); $("play").click(); }
    else if (e.key === "+") zoom(1.25);
    else if (e.key === "-") zoom(0.8);
  });

  load();
  requestAnimationFrame(tick);
})();
