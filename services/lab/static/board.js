// The participant's touch screen (thesis 7.1.3): it draws what the server's view says
// and sends touches; it decides nothing. See services/lab/hub.py for the protocol.
"use strict";
(function () {
  const { connect, el, now } = window.pairplayLab;
  const { faceSvg } = window.pairplayFaces;
  const grid = document.getElementById("grid");
  const wrong = document.getElementById("wrong");
  const prompt = document.getElementById("prompt");
  const banner = document.getElementById("banner");
  const api = window.pairplay = { state: null, role: "", rejected: [], sent: 0, turnBack: false, renders: 0 };
  let msgId = Number(sessionStorage.getItem("pairplay-msg") || 0);
  let seenTurn = null;  // id of the last resolved turn drawn (null: nothing drawn yet)
  let holdUntil = 0, holdTimer = null, pending = -1;
  let offline = "";  // what the page says while its WebSocket is down ("": connected)
  // the hub refused the last touch as late (its clock stopped while the device slept: common.js opens a new
  // socket): the page asks for it again, rather than leave the card simply not turning; gone at the next touch
  let again = false;

  const cards = [];
  for (let i = 0; i < 18; i++) {
    const b = el("button", "card down");
    b.type = "button";
    b.dataset.card = i;
    b.setAttribute("aria-label", `card ${Math.floor(i / 6) + 1}-${i % 6 + 1}`);
    b.addEventListener("click", (ev) => touch(i, performance.timeOrigin + ev.timeStamp));
    grid.appendChild(b);
    cards.push(b);
  }
  api.canTouch = () => {  // for scripts and tests: would a touch on a covered card be sent now?
    const s = api.state;
    return !!s && api.role === "player" && !s.paused && link.up() && performance.now() >= holdUntil && pending < 0 &&
      ["first", "looking", "thinking", "second"].includes(s.phase);
  };
  const nextId = () => { msgId += 1; sessionStorage.setItem("pairplay-msg", msgId); return msgId; };
  api.nextId = nextId;  // the page's message counter (scripts that send their own messages use it)

  function touch(i, pageMs) {
    const s = api.state;
    if (!s || api.role !== "player" || s.paused || performance.now() < holdUntil) return;
    if (!["first", "looking", "thinking", "second"].includes(s.phase) || s.cards[i].state !== "down") return;
    if (pending >= 0 || (s.first >= 0 && s.first === i)) return;
    // the card waits for the game's answer only if the touch went out: a touch while offline is dropped
    // (the page says "Reconnecting…"), never left pending for an answer that cannot come
    if (!link.send({ type: "pick", id: nextId(), round: s.round, turn: s.turn, card: i, page_ms: pageMs })) return;
    again = false;
    api.sent += 1;
    pending = i;
    cards[i].classList.add("pending");
  }
  wrong.addEventListener("click", (ev) => {
    const s = api.state;
    if (!s || api.role !== "player" || s.paused || s.phase !== "second" || s.attempt < 0) return;
    // disabled only once sent: offline, the press is dropped and the button stays as the view says
    if (link.send({ type: "wrong", id: nextId(), round: s.round, turn: s.turn, attempt: s.attempt,
                    page_ms: performance.timeOrigin + ev.timeStamp })) { wrong.disabled = true; again = false; }
  });

  function drawCard(b, state, face, extra) {
    b.className = `card ${state}` + (extra ? " " + extra : "");
    b.dataset.state = state;
    b.dataset.face = face;
    const html = face >= 0 ? faceSvg(face) : "";
    if (b.dataset.html !== html) { b.innerHTML = html; b.dataset.html = html; }
  }

  function render() {
    const s = api.state;
    if (!s) return;
    api.renders += 1;
    const holding = performance.now() < holdUntil;
    document.getElementById("round").textContent =
      s.round >= 0 ? `Round ${Math.min(s.round + 1, s.rounds)} of ${s.rounds}` : "Round –";
    document.getElementById("pairs").textContent = `Pairs ${s.matches} of 9`;
    const lt = s.last_turn;
    for (let i = 0; i < 18; i++) {
      const c = s.cards[i];
      let state = c.state, face = c.face, extra = "";
      if (holding && lt && lt.cards.includes(i)) {  // the missed pair stays up for the turn-back delay
        state = "up"; face = lt.faces[lt.cards.indexOf(i)]; extra = "miss";
      } else if (lt && lt.matched && lt.cards.includes(i) && lt.id === seenTurn && performance.now() < api.matchFlash) {
        extra = "just-matched";
      }
      if (i === s.observed && state !== "matched" && !holding) extra += " observed";
      if (i === pending && state === "down") extra += " pending";
      drawCard(cards[i], state, face, extra.trim());
    }
    const player = api.role === "player";
    wrong.disabled = !(player && link.up() && !s.paused && s.phase === "second" && s.attempt >= 0 && !holding);
    wrong.classList.toggle("hidden", api.role === "viewer");
    let text = {
      starting: "Waiting for the game to start…", first: "Pick a card", looking: "Look for its pair",
      thinking: "The robot is thinking…", second: "Find its pair", over: "The game is over. Thank you!",
    }[s.phase] || "";
    // a game the experimenter (or a signal) stopped asks no questionnaire: the page says it was stopped
    if (s.phase === "over" && stopped(s)) text = "The game was stopped. Thank you!";
    // offline, the page says so whatever else redraws it (a turn-back timer): it takes no touch until back
    prompt.textContent = offline ? offline : s.paused ? "The game is paused: please wait" :
      holding ? "Not a pair" : again && player ? "That touch came too late: please touch again" :
      (s.notice && player ? s.notice.reason : text);
    prompt.dataset.phase = s.phase;
    document.body.classList.toggle("read-only", !player);
    document.body.dataset.role = api.role;
    document.body.dataset.phase = s.phase;
    document.body.classList.toggle("paused", !!s.paused);
  }

  function onState(s, role) {
    const lt = s.last_turn;
    if (lt && seenTurn !== null && lt.id !== seenTurn) {  // a turn resolved while we watched
      if (!lt.matched && s.turn_back_ms > 0) {
        holdUntil = performance.now() + s.turn_back_ms;
        api.turnBack = true;
        clearTimeout(holdTimer);
        holdTimer = setTimeout(() => { api.turnBack = false; render(); }, s.turn_back_ms + 5);
      } else if (lt.matched) {
        api.matchFlash = performance.now() + 600;
        setTimeout(render, 610);
      }
    }
    seenTurn = lt ? lt.id : 0;
    const was = api.state;
    if (was && (s.round !== was.round || s.turn !== was.turn || s.phase !== was.phase)) again = false;  // moved on
    if (pending >= 0 && (s.cards[pending].state !== "down" || s.turn !== (api.state && api.state.turn))) pending = -1;
    if (pending >= 0 && s.notice && s.notice.card === pending) pending = -1;
    api.state = s;
    api.role = role;
    if (s.phase === "over" && role === "player" && s.questionnaire && !stopped(s) && !api.askedQuestionnaire) {
      askQuestionnaire();
    }
    banner.classList.toggle("hidden", role === "player");
    if (role === "viewer") banner.textContent = "Read-only: another screen is playing this session";
    render();
  }
  const stopped = (s) => ["aborted", "interrupted"].includes(s.ended);  // SessionEnded's reason
  // In a study (services/console), a questionnaire follows a game that was not stopped if the participant is
  // asked one (the view's `questionnaire`, hub.py): the board becomes it. Elsewhere (`pairplay lab`) it asks
  // nothing: the route is the study's, and asking logged a 404 (403 for a participant asked nothing).
  async function askQuestionnaire() {
    api.askedQuestionnaire = true;
    const { session, token } = window.pairplayLab;
    const q = `session=${encodeURIComponent(session)}&token=${encodeURIComponent(token)}`;
    try {
      const r = await fetch(`/api/questionnaire?${q}`);
      if (r.ok) location.assign(`/questionnaire?${q}`);
    } catch (e) { /* no questionnaire: the board shows the end */ }
  }
  const link = connect("board", {
    onState,
    onLink: (up, code) => {
      document.body.classList.toggle("offline", !up);
      offline = up ? "" : code === 4403 ? "This link is not valid" : "Reconnecting…";
      if (!up) {
        pending = -1;  // a touch in flight is answered by the view sent on reconnecting, or not at all
        prompt.textContent = offline;
        wrong.disabled = true;
      }
    },
    onRejected: (m) => { api.rejected.push(m); pending = -1; if (m.late) again = true; render(); },
  });
  api.link = link;
})();
