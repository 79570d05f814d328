// Rover dashboard page: draws one state object (see dashboard/view.py) at a time.
// Live pages follow /api/stream (server-sent events, newest state only);
// the mission viewer fetches /api/frame/<i> as the slider moves.
"use strict";

const $ = (id) => document.getElementById(id);

function fmt(v, digits, unit) {
  if (v === null || v === undefined || Number.isNaN(v)) return "n/a";
  return Number(v).toFixed(digits) + (unit ? " " + unit : "");
}

function setFig(id, value, text) {
  const el = $(id);
  el.dataset.value = value === null || value === undefined ? "" : String(value);
  el.textContent = text;
}

function drawCurves(h) {
  const c = $("curves"), g = c.getContext("2d"), W = c.width, H = c.height, pad = 24;
  g.clearRect(0, 0, W, H);
  g.strokeStyle = "#333a42"; g.fillStyle = "#7d8894"; g.font = "10px sans-serif"; g.lineWidth = 1;
  for (const p of [0, 50, 100]) {
    const y = H - pad - (H - 2 * pad) * p / 100;
    g.beginPath(); g.moveTo(pad, y); g.lineTo(W - 4, y); g.stroke(); g.fillText(p + "%", 0, y + 3);
  }
  const t = h.t || [];
  if (t.length < 2) return;
  const t0 = t[0], t1 = t[t.length - 1] || 1, span = Math.max(1e-6, t1 - t0);
  const X = (v) => pad + (W - pad - 4) * (v - t0) / span;
  const maxCollected = Math.max(6, ...(h.collected || []).filter((v) => v !== null));
  const series = [["mapped", "#2896ff", 100], ["fidelity", "#ff9f28", 100], ["collected", "#3ddc5a", maxCollected]];
  for (const [key, colour, top] of series) {
    g.strokeStyle = colour; g.lineWidth = 2; g.beginPath();
    let started = false;
    h[key].forEach((v, i) => {
      if (v === null) return;
      const y = H - pad - (H - 2 * pad) * v / top;
      if (!started) { g.moveTo(X(t[i]), y); started = true; } else g.lineTo(X(t[i]), y);
    });
    g.stroke();
  }
  g.fillStyle = "#7d8894";
  g.fillText(fmt(t0, 0, "s"), pad, H - 6); g.fillText(fmt(t1, 0, "s"), W - 44, H - 6);
}

function render(state) {
  const f = state.figures;
  if (state.images) {
    for (const key of ["camera", "vision", "map"]) {
      if (state.images[key]) $("img-" + key).src = state.images[key];
    }
  }
  setFig("fig-t", f.t, fmt(f.t, 1, "s"));
  setFig("fig-mapped", f.mapped, fmt(f.mapped, 1, "%"));
  setFig("fig-fidelity", f.fidelity, fmt(f.fidelity, 1, "%"));
  setFig("fig-located", f.located, f.located === null ? "n/a" : `${f.located}${f.samples ? " / " + f.samples : ""}`);
  setFig("fig-collected", f.collected, f.collected === null ? "n/a" : `${f.collected}${f.samples ? " / " + f.samples : ""}`);
  setFig("fig-mode", f.mode, f.mode || "–");
  const target = f.target ? `(${fmt(f.target[0], 1)}, ${fmt(f.target[1], 1)})` : "none";
  setFig("fig-target", f.target, (f.goal ? f.goal + " → " : "") + target);
  setFig("fig-speed", f.speed, fmt(f.speed, 2, "m/s"));
  setFig("fig-throttle", f.throttle, fmt(f.throttle, 2));
  setFig("fig-brake", f.brake, fmt(f.brake, 2));
  setFig("fig-steer", f.steer, fmt(f.steer, 1, "°"));
  setFig("fig-pos", f.x, `(${fmt(f.x, 1)}, ${fmt(f.y, 1)}) yaw ${fmt(f.yaw, 0, "°")}`);
  setFig("fig-hz", f.telemetry_hz, f.telemetry_hz === null || f.telemetry_hz === undefined
    ? "–" : fmt(f.telemetry_hz, 0, "frames/s"));
  drawCurves(state.history || {});
  const list = $("events");
  list.replaceChildren(...(state.events || []).slice().reverse().map(([t, text]) => {
    const li = document.createElement("li");
    li.textContent = `${fmt(t, 1, "s")}  ${text}`;
    return li;
  }));
  document.body.dataset.version = String(state.version);
  document.body.dataset.frame = String(f.frame);
}

function setConn(text, cls) { const el = $("conn"); el.textContent = text; el.className = "pill " + (cls || ""); }

function live() {
  const source = new EventSource("/api/stream");
  source.onopen = () => setConn("live", "ok");
  source.onerror = async () => {
    setConn("reconnecting…", "bad");
    try {  // the mission may have ended and the server now shows the finished mission
      const info = await (await fetch("/api/info")).json();
      if (info.kind === "viewer") { source.close(); start(info); }
    } catch (e) { /* server gone: EventSource keeps retrying */ }
  };
  source.onmessage = (ev) => { try { render(JSON.parse(ev.data)); } catch (e) { console.error(e); } };
}

function viewer(info) {
  $("scrubber").hidden = false;
  const scrub = $("scrub"), label = $("scrub-label");
  scrub.max = String(info.frames - 1);
  let pending = null, busy = false, timer = null;
  async function show(i) {
    if (busy) { pending = i; return; }
    busy = true;
    try {
      const r = await fetch(`/api/frame/${i}`);
      if (r.ok) {
        const s = await r.json();
        render(s);
        label.textContent = `${i + 1} / ${info.frames}  (${fmt(s.figures.t, 0, "s")})`;
      }
    } finally {
      busy = false;
      if (pending !== null) { const j = pending; pending = null; show(j); }
    }
  }
  scrub.addEventListener("input", () => show(Number(scrub.value)));
  $("play").addEventListener("click", () => {
    if (timer) { clearInterval(timer); timer = null; $("play").textContent = "play"; return; }
    $("play").textContent = "pause";
    timer = setInterval(() => {
      const next = Number(scrub.value) + 1;
      if (next > Number(scrub.max)) { clearInterval(timer); timer = null; $("play").textContent = "play"; return; }
      scrub.value = String(next); show(next);
    }, 200);
  });
  setConn("finished mission", "ok");
  show(Number(scrub.max));
  scrub.value = scrub.max;
}

function start(info) {
  $("kind").textContent = info.kind === "viewer" ? "mission viewer" : "live";
  $("title").textContent = info.title || "";
  document.title = `Rover dashboard – ${info.title || info.kind}`;
  if (info.kind === "viewer") viewer(info); else live();
}

fetch("/api/info").then((r) => r.json()).then(start);
