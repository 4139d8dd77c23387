// The experimenter's console: polls /api/console/state and renders it; every button is one POST.
"use strict";
const token = new URLSearchParams(location.search).get("token") || "";
const $ = (id) => document.getElementById(id);
let last = null;
// A refusal stays on screen until the experimenter acts again (the next poll does not replace it), and
// a server that does not answer is said, every control off until a poll gets an answer again.
let held = false;  // a refusal is on screen
let down = false;  // the last request got no answer at all
const GONE = "the lab server does not answer (stopped?): the controls work again once it does";
// A poll (a GET) with no answer within POLL_DEADLINE_MS counts as no answer: on a network that dropped without
// closing the connection (half-open TCP) a fetch waits for minutes, and the page kept its last view without a
// word (trial29 F7's kind). Only reads: a POST may take a while (a combine) and is not to be sent twice.
const POLL_DEADLINE_MS = 5000;

async function api(path, body) {
  let r;
  try {
    r = await fetch(path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token),
                    body === undefined ? {signal: AbortSignal.timeout(POLL_DEADLINE_MS)} : {method: "POST", headers: {"content-type": "application/json"},
                                               body: JSON.stringify(body)});
  } catch (e) { serverGone(); e.said = true; throw e; }  // no answer (fetch's TypeError), not a refusal
  const data = await r.json().catch(() => ({error: "bad answer from the lab server"}));
  if (!r.ok) {
    held = true;
    say(data.error || ("HTTP " + r.status), true);
    throw Object.assign(new Error(data.error), {said: true});
  }
  return data;
}
function serverGone() {
  if (!down) {
    down = true;
    document.querySelectorAll("button, input, select").forEach((b) => { if (!b.disabled) { b.disabled = true; b.dataset.off = "1"; } });
  }
  say(GONE, true);
}
function serverBack() {
  if (!down) return;
  down = false;
  document.querySelectorAll("[data-off]").forEach((b) => { b.disabled = false; delete b.dataset.off; });
  if (!held) say("");
}
// acting again (any button) is when a refusal on screen may go
document.addEventListener("click", (ev) => { if (ev.target.closest("button")) held = false; }, true);
// a control's handler: what api() refused or could not send is said on the page, not thrown at it
const act = (fn) => (ev) => { Promise.resolve().then(() => fn(ev)).catch((e) => { if (!e || !e.said) throw e; }); };
function say(text, error) { const m = $("message"); m.textContent = text; m.className = error ? "error" : ""; }
function el(tag, text, cls) { const e = document.createElement(tag); if (text !== undefined) e.textContent = text; if (cls) e.className = cls; return e; }

function renderCurve(picks) {
  const svg = $("curve"); svg.innerHTML = "";
  const ns = "http://www.w3.org/2000/svg";
  const max = Math.max(40, ...picks), w = 320, h = 140, pad = 22;
  const y = (v) => h - pad - (v / max) * (h - 2 * pad);
  const x = (i) => pad + (picks.length > 1 ? i * (w - 2 * pad) / (picks.length - 1) : 0);
  const perfect = document.createElementNS(ns, "line");
  perfect.setAttribute("x1", pad); perfect.setAttribute("x2", w - pad); perfect.setAttribute("y1", y(18)); perfect.setAttribute("y2", y(18));
  perfect.setAttribute("stroke", "#aab"); perfect.setAttribute("stroke-dasharray", "3 3"); svg.appendChild(perfect);
  if (!picks.length) return;
  const line = document.createElementNS(ns, "polyline");
  line.setAttribute("points", picks.map((v, i) => x(i) + "," + y(v)).join(" "));
  line.setAttribute("fill", "none"); line.setAttribute("stroke", "#2b6de0"); line.setAttribute("stroke-width", "2");
  svg.appendChild(line);
  picks.forEach((v, i) => {
    const c = document.createElementNS(ns, "circle"); c.setAttribute("cx", x(i)); c.setAttribute("cy", y(v)); c.setAttribute("r", 3.5);
    c.setAttribute("fill", "#2b6de0"); svg.appendChild(c);
    const t = document.createElementNS(ns, "text"); t.setAttribute("x", x(i) - 6); t.setAttribute("y", y(v) - 6);
    t.setAttribute("font-size", "10"); t.textContent = v; svg.appendChild(t);
  });
}

function render(s) {
  last = s;
  $("title").textContent = s.study.title || s.study.id;
  $("study-line").textContent = `study ${s.study.id}, folder ${s.study.folder}; key file: ${s.study.key_file ? "yes (outside the folder)" : "none (ids only)"}`;
  $("label-wrap").style.display = s.study.key_file ? "" : "none";
  // consent is recorded with the study's form now: what the experimenter confirms the person signed
  $("consent-text").textContent = `signed the consent form${s.consent_form ? ` "${s.consent_form}"` : ""} (records consent now)`;
  const phases = $("register-phase");
  if (phases.options.length !== s.study.phases.length) {
    phases.innerHTML = ""; s.study.phases.forEach((p) => phases.appendChild(el("option", p)));
  }
  const ul = $("participants"); ul.innerHTML = "";
  s.participants.forEach((p) => {
    const li = el("li", `${p.id} (joins ${p.joins}; ${p.games} valid game(s)${p.scripted ? `; scripted: ${p.scripted}` : ""}; ` +
                        (p.consent ? `consent: ${p.consent}` : "no consent recorded") +
                        // a consent to an earlier form only (protocol consent-form): they wait as without one
                        (p.consent_problem ? (p.consent ? `; ${p.consent_problem}` : "") + ": plays only as a persona)" : ")"));
    if (p.consent_problem) li.classList.add("no-consent");
    ul.appendChild(li);
  });
  // an id a record shows given that the journal does not register (a crash, a hand edit): what it is, never a participant
  s.unregistered.forEach((u) => { const li = el("li", `${u.id}: ${u.note}`); li.className = "unregistered"; ul.appendChild(li); });
  if (s.key_file_problem) { const li = el("li", s.key_file_problem); li.className = "unregistered"; ul.appendChild(li); }
  const sel = $("data-participant"), keep = sel.value; sel.innerHTML = "";
  s.participants.forEach((p) => sel.appendChild(el("option", p.id)));
  if ([...sel.options].some((o) => o.value === keep)) sel.value = keep;

  const plan = $("plan"); plan.innerHTML = "";
  s.plan.forEach((p) => {
    const li = el("li", p.label + (p.blocked && !p.done ? ` (${p.blocked})` : "")
      + (p.waits && !p.done ? ` (waits for consent: ${p.waits})` : "") + (p.note ? ` (${p.note})` : ""));
    li.className = p.done ? "done" : (p.blocked ? "blocked" : "");
    if (s.next && p.label === s.next.label) li.classList.add("next");
    plan.appendChild(li);
  });
  $("next-step").textContent = s.next ? `next: ${s.next.label}` : s.participants.length ? "the plan is complete" : "nobody is registered: register participants first";
  $("run-next").disabled = s.busy || !s.next || !!s.next.blocked;

  const L = s.live;
  $("live-session").textContent = L.session ? `${L.session} (${L.participant}${L.scripted ? ` (scripted: ${L.scripted})` : ""}, ${L.phase} game ${L.game + 1})` : "none";
  $("live-state").textContent = L.state + (L.paused ? " (paused)" : "");
  $("live-board").textContent = L.session ? (L.board ? "connected" : "waiting for the board page") : "";
  const bu = $("live-board");
  if (L.board_url) { const a = el("a", " open the board"); a.href = L.board_url; a.target = "_blank"; a.id = "board-link"; bu.appendChild(a); }
  $("live-round").textContent = L.session ? `${L.round + 1} of ${L.rounds}` : "";
  $("live-picks").textContent = L.session ? L.picks : "";
  $("live-suggestion").textContent = L.suggestion;
  $("live-robot").textContent = L.robot;
  // what the game refused (a board's late touch among them): the experimenter sees a page that cannot play
  $("live-refused").textContent = L.session && L.refused ? `${L.refused} (last: ${L.last_refused})` : "";
  $("robot-warning").textContent = s.robot_warning || ""; $("robot-warning").hidden = !s.robot_warning;
  const q = $("live-questionnaire"); q.innerHTML = "";
  if (L.questionnaire_url) { const a = el("a", L.state === "questionnaire" ? "awaiting answers: open the questionnaire" : "after the game"); a.href = L.questionnaire_url; a.id = "questionnaire-link"; a.target = "_blank"; q.appendChild(a); }
  $("pause").disabled = L.state !== "playing" || L.paused;
  $("resume").disabled = !L.paused;
  $("abort").disabled = !(L.state === "playing" || L.state === "questionnaire");
  $("skip-questionnaire").disabled = L.state !== "questionnaire";
  renderCurve(L.picks_per_round);

  const comb = $("combined"); comb.innerHTML = "";
  for (const [phase, c] of Object.entries(s.combined)) {
    comb.appendChild(el("h3", `${phase}: ${c.users.join(", ")} -> ${c.output}`));
    // a bias policy made with a game marked invalid since; the earlier ones kept for the games played on them
    if (c.flawed) { const w = el("p", `${c.output} was ${c.flawed}: the plan combines it again`, "partial"); w.id = "flawed-" + phase; comb.appendChild(w); }
    c.earlier.forEach((e) => comb.appendChild(el("p", `earlier: ${e.output}` + (e.flawed ? `, ${e.flawed}` : "") + `; played on it: ${e.played_on.join(", ") || "none"}`)));
    const t = el("table"); const hd = t.insertRow(); ["user", "speech incompatible", "head incompatible", "smile", "gaze"].forEach((h) => hd.appendChild(el("th", h)));
    for (const [u, p] of Object.entries(c.profiles)) {
      const r = t.insertRow(); [u, (100 * p.speech).toFixed(1) + "%", (100 * p.head).toFixed(1) + "%", p.facial ? "yes" : "no", p.gaze ? "yes" : "no"].forEach((v) => r.insertCell().textContent = v);
    }
    comb.appendChild(t);
    if (c.partial) { const w = el("p", c.partial, "partial"); w.id = "partial-" + phase; comb.appendChild(w); }
    const rules = el("table", undefined, "rules"); rules.id = "rules-" + phase;
    const rh = rules.insertRow(); ["state", "action", "rule that decided it"].forEach((h) => rh.appendChild(el("th", h)));
    c.states.forEach((st) => { const r = rules.insertRow(); [st.state, st.action, st.rule].forEach((v) => r.insertCell().textContent = v); });
    comb.appendChild(rules);
  }
  if (!Object.keys(s.combined).length) comb.textContent = "not combined yet";

  const tb = $("games").tBodies[0]; tb.innerHTML = "";
  s.games.forEach((g) => {
    const r = tb.insertRow(); if (g.invalid) r.className = "invalid";
    [g.session, g.participant + (g.scripted ? ` (scripted: ${g.scripted})` : ""), g.phase, g.game, g.outcome + (g.reason ? ` (${g.reason})` : "") + (g.invalid ? ` invalid: ${g.invalid}` : "") + (g.bias_flawed ? ` (played on ${g.bias}, ${g.bias_flawed})` : ""),
     g.questionnaire ? "answered" : "-"].forEach((v) => r.insertCell().textContent = v);
    const b = el("button", "mark invalid"); b.disabled = !!g.invalid || g.outcome === "running";
    b.onclick = () => { const why = prompt(`Why is ${g.session} invalid?`); if (why) api("/api/console/control/invalid", {session: g.session, reason: why}).then((r) => say(r.said || `${g.session} marked invalid`), (e) => { if (!e.said) throw e; }); };
    r.insertCell().appendChild(b);
  });
  if (s.last.step && !held) say(`${s.last.step}: ${s.last.message}`, !s.last.ok);
  $("report-link").innerHTML = "";
  if (s.report) { const a = el("a", "report.md"); a.href = "/api/console/report/report.md?token=" + encodeURIComponent(token); a.id = "report-md"; $("report-link").appendChild(a); }
}

async function poll() {
  try {
    const s = await api("/api/console/state");
    serverBack();
    render(s);
  } catch (e) {  // a refusal, or no answer: said by api(); anything else is a fault of this page, reported
    if (!e || !e.said) setTimeout(() => { throw e; });
  }
  setTimeout(poll, 250);
}

$("register-form").onsubmit = (ev) => { ev.preventDefault(); register(); };
const register = act(async () => {
  const r = await api("/api/console/register", {phase: $("register-phase").value, count: parseInt($("register-count").value, 10) || 1, label: $("register-label").value,
                                               consent: $("register-consent").checked});
  $("register-label").value = ""; $("register-consent").checked = false;
  say("registered " + r.registered.join(", ") + (r.consent ? " (consent recorded)" : " (no consent recorded: Record consent once signed)"));
});
$("run-next").onclick = act(async () => { const r = await api("/api/console/next", {}); say("started: " + r.started); });
$("pause").onclick = act(() => api("/api/console/control/pause", {}));
$("resume").onclick = act(() => api("/api/console/control/resume", {}));
$("abort").onclick = act(() => api("/api/console/control/abort", {reason: $("abort-reason").value}));
$("skip-questionnaire").onclick = act(() => api("/api/console/control/skip-questionnaire", {}));
$("record-consent").onclick = act(async () => {
  // given_at as typed: the server parses it as the CLI's --given-at does, and refuses in its words
  const r = await api("/api/console/consent", {participant: $("data-participant").value, given_at: $("consent-given-at").value});
  $("consent-given-at").value = "";
  say(`${r.consent}: consent recorded: ${r.given}`);
});
$("export").onclick = act(async () => {
  const r = await api("/api/console/export", {participant: $("data-participant").value});
  const res = $("data-result"); res.innerHTML = ""; const a = el("a", "download " + r.export.split("/").pop()); a.href = r.export + "?token=" + encodeURIComponent(token); a.id = "export-link"; res.appendChild(a);
  if (r.left_out && r.left_out.length) res.appendChild(el("span", " (left out: " + r.left_out.join("; ") + ")"));
});
$("delete").onclick = act(async () => {
  const pid = $("data-participant").value;
  const r = await api("/api/console/delete", {participant: pid, confirm: $("delete-confirm").value,
                                             consent_withdrawn: $("delete-withdrawn").checked});
  $("delete-confirm").value = ""; $("delete-withdrawn").checked = false;
  $("data-result").textContent = `deleted ${pid}${r.deleted.consent_withdrawn ? " (consent withdrawn)" : ""}: ${r.deleted.sessions_removed} games, ${r.deleted.files_removed} files` +
    (r.deleted.merged_policies_using_them.length ? `; merged policies that used them: ${r.deleted.merged_policies_using_them.join(", ")}` : "") +
    (r.unnamed ? `; their name replaced by "deleted" in ${r.unnamed} kept reason${r.unnamed > 1 ? "s" : ""} of other people's games` : "") +
    (r.no_key_line ? `; they had no line in the key file: their name is not known here, so other people's kept reasons were not checked for it` : "") +
    r.erased_copies.map(p => `; erased pairplay's unchanged copy ${p}`).join("") +
    r.not_erased.map(p => `; NOT erased, a copy made outside the study folder's own places (changed or moved): ${p} (erase it by hand)`).join("") +
    r.kept.map(k => `; kept ${k.file}, not written by the report` + (k.names_them ? ` (it names ${pid}: edit it by hand)` : "")).join("");
});
$("report").onclick = act(() => api("/api/console/report", {}));
poll();
