// The robot's stand-in (issue 14 item 4): the open suggestion in words, the card region its
// head or gaze part points at with an arrow from the observed card, and what the robot did.
"use strict";
(function () {
  const { connect, el } = window.pairplayLab;
  const { faceSvg } = window.pairplayFaces;
  const board = document.getElementById("board");
  const NS = "http://www.w3.org/2000/svg";
  const api = window.pairplay = { state: null, renders: 0 };
  const cards = [];
  for (let i = 0; i < 18; i++) { const d = el("div", "card down"); d.dataset.card = i; board.appendChild(d); cards.push(d); }
  const arrow = document.createElementNS(NS, "svg");
  arrow.setAttribute("class", "arrow");
  board.appendChild(arrow);

  function center(i) {
    const b = board.getBoundingClientRect(), r = cards[i].getBoundingClientRect();
    return [r.left - b.left + r.width / 2, r.top - b.top + r.height / 2];
  }
  function drawArrow(from, region) {
    const b = board.getBoundingClientRect();
    arrow.setAttribute("viewBox", `0 0 ${b.width} ${b.height}`);
    arrow.replaceChildren();
    if (from < 0 || !region.length || (region.length === 1 && region[0] === from)) return;
    const [x0, y0] = center(from);
    const pts = region.map(center);
    const x1 = pts.reduce((a, p) => a + p[0], 0) / pts.length, y1 = pts.reduce((a, p) => a + p[1], 0) / pts.length;
    const len = Math.hypot(x1 - x0, y1 - y0);
    if (len < 1) return;
    const ux = (x1 - x0) / len, uy = (y1 - y0) / len, head = Math.min(28, len / 3);
    const x2 = x1 - ux * 10, y2 = y1 - uy * 10;
    const line = document.createElementNS(NS, "path");
    line.setAttribute("d", `M${x0},${y0} L${x2},${y2}`);
    line.setAttribute("stroke", "#1f5fa8"); line.setAttribute("stroke-width", "7");
    line.setAttribute("stroke-linecap", "round"); line.setAttribute("opacity", "0.85");
    const tip = document.createElementNS(NS, "path");
    tip.setAttribute("d", `M${x2 + ux * 4},${y2 + uy * 4} L${x2 - ux * head - uy * head * 0.6},${y2 - uy * head + ux * head * 0.6} ` +
      `L${x2 - ux * head + uy * head * 0.6},${y2 - uy * head - ux * head * 0.6} Z`);
    tip.setAttribute("fill", "#1f5fa8"); tip.setAttribute("opacity", "0.9");
    arrow.append(line, tip);
  }
  const ms = (a, b) => (a && b ? `${((a - b) / 1e6).toFixed(1)} ms` : "–");

  function render(s) {
    api.state = s;
    api.renders += 1;
    document.getElementById("round").textContent =
      s.round >= 0 ? `Round ${Math.min(s.round + 1, s.rounds)} of ${s.rounds}` : "Round –";
    document.getElementById("pairs").textContent = `Pairs ${s.matches} of 9`;
    document.getElementById("who").textContent = s.participant || "";
    const sug = s.suggestion;
    const region = sug ? sug.seen : [];
    const visual = !!sug && !(sug.parts.head === "head still" && sug.parts.gaze === "no gaze");
    for (let i = 0; i < 18; i++) {
      const c = s.cards[i];
      let cls = `card ${c.state}`;
      if (i === s.observed && c.state !== "matched") cls += " observed";
      if (visual && region.includes(i)) cls += " region";
      cards[i].className = cls;
      const html = c.face >= 0 ? faceSvg(c.face) : "";
      if (cards[i].dataset.html !== html) { cards[i].innerHTML = html; cards[i].dataset.html = html; }
    }
    drawArrow(visual ? sug.observed : -1, visual ? region : []);
    document.getElementById("speech").textContent = !sug ? (s.phase === "over" ? "Thank you!" : "…")
      : sug.parts.speech === "say nothing" ? (sug.parts.facial === "smile" ? "🙂 (smiles)" : "(says nothing)")
      : sug.parts.speech.replace(/^"|"$/g, "");
    const parts = document.getElementById("parts");
    parts.replaceChildren();
    if (sug) {
      for (const [k, v] of [["action", `${sug.action} (${sug.chosen_by}), attempt ${sug.attempt + 1}`],
                            ["face", sug.parts.facial], ["head", sug.parts.head], ["gaze", sug.parts.gaze],
                            ["looking at", sug.observed_at]]) {
        parts.append(el("dt", "", k), el("dd", "", v));
      }
    }
    const robot = document.getElementById("robot");
    robot.replaceChildren();
    if (s.robot && s.robot.length) {
      const t = el("table");
      const h = t.insertRow();
      for (const k of ["round.turn.try", "action", "robot", "outcome", "sent after", "done after"]) h.append(el("th", "", k));
      for (const r of s.robot.slice().reverse()) {
        const row = t.insertRow();
        for (const v of [`${r.round + 1}.${r.turn + 1}.${r.attempt + 1}`, r.action, r.backend,
                         r.outcome + (r.error ? ` (${r.error})` : ""), ms(r.sent_ns, r.received_ns), ms(r.done_ns, r.received_ns)]) {
          row.append(el("td", "", String(v)));
        }
      }
      robot.append(el("div", "", "What the robot did (newest first):"), t);
    }
    document.getElementById("prompt").textContent = { starting: "Waiting for the game", first: "First card",
      looking: "Looking", thinking: "Choosing a suggestion…", second: "Suggesting", over: "Game over" }[s.phase] || "";
    document.body.dataset.phase = s.phase;
  }
  window.addEventListener("resize", () => api.state && render(api.state));
  api.link = connect("mirror", { onState: (s) => render(s), onLink: (up) => document.body.classList.toggle("offline", !up) });
})();
