// The questionnaire after a game: items from the lab server, answers posted back (QuestionnaireAnswered).
"use strict";
const params = new URLSearchParams(location.search);
const session = params.get("session") || "", token = params.get("token") || "";
const $ = (id) => document.getElementById(id);
function el(tag, text, cls) { const e = document.createElement(tag); if (text !== undefined) e.textContent = text; if (cls) e.className = cls; return e; }
function status(text, error) { $("q-status").textContent = text; $("q-status").className = error ? "error" : ""; }

function build(q) {
  $("q-title").textContent = q.title; $("q-intro").textContent = q.intro;
  const form = $("q-form"); form.innerHTML = "";
  q.items.forEach((item) => {
    const fs = el("fieldset"); fs.id = "item-" + item.id; fs.dataset.kind = item.kind;
    fs.appendChild(el("legend", item.text + (item.required ? "" : " (optional)")));
    if (item.kind === "likert" || item.kind === "choice") {
      const row = el("div", undefined, item.kind === "likert" ? "scale" : "choices");
      if (item.kind === "likert" && item.low) row.appendChild(el("span", item.low, "end"));
      const values = item.kind === "likert" ? Array.from({length: item.scale}, (_, i) => String(i + 1)) : item.options;
      values.forEach((v, i) => {
        const lab = el("label"); const inp = el("input"); inp.type = "radio"; inp.name = item.id; inp.value = v;
        inp.id = `${item.id}-${i}`; lab.appendChild(inp); lab.appendChild(document.createTextNode(v)); row.appendChild(lab);
      });
      if (item.kind === "likert" && item.high) row.appendChild(el("span", item.high, "end"));
      fs.appendChild(row);
    } else {
      const ta = el("textarea"); ta.name = item.id; ta.maxLength = item.max_chars; fs.appendChild(ta);
    }
    form.appendChild(fs);
  });
  const send = el("button", "Send my answers"); send.type = "submit"; send.id = "q-send"; form.appendChild(send);
  form.onsubmit = submit;
}

async function submit(ev) {
  ev.preventDefault();
  const answers = {};
  document.querySelectorAll("#q-form fieldset").forEach((fs) => {
    const id = fs.id.slice(5);
    if (fs.dataset.kind === "text") { const v = fs.querySelector("textarea").value.trim(); if (v) answers[id] = v; }
    else { const c = fs.querySelector("input:checked"); if (c) answers[id] = c.value; }
  });
  // the link's session and token in the URL too: the server checks them before it reads the body
  const link = `session=${encodeURIComponent(session)}&token=${encodeURIComponent(token)}`;
  let r;
  try {
    r = await fetch(`/api/questionnaire/answer?${link}`, {method: "POST", headers: {"content-type": "application/json"},
                                                          body: JSON.stringify({session, token, answers})});
  } catch (e) {  // never sent (the server is unreachable): the answers stay on the form, to send again
    status("The answers could not be sent (no connection to the lab server): please press Send again", true);
    return;
  }
  const data = await r.json().catch(() => ({}));
  if (!r.ok && data.spent !== "answered") { status(data.error || "could not send", true); return; }  // (sent twice: recorded)
  answered = true;
  $("q-form").innerHTML = ""; status("Thank you! Your answers are recorded.");
}

// The page follows the game's questionnaire until it is answered: once the link stops working (the
// experimenter skipped it, or aborted), the form goes and the page says the questionnaire is closed.
let built = false, answered = false, loaded = false, cut = false;  // loaded: the link worked once
async function load() {
  if (answered) return;
  let r;
  try {
    // no answer within 5 s is none: on a half-open connection (a network that dropped without closing it) a
    // fetch waits for minutes, and the page would keep its last view without a word
    r = await fetch(`/api/questionnaire?session=${encodeURIComponent(session)}&token=${encodeURIComponent(token)}`,
                    {signal: AbortSignal.timeout(5000)});
  } catch (e) {  // the lab server does not answer (or not in time): say so, keep what is typed, try again
    status("No connection to the lab server: retrying…", true);
    cut = true;
    setTimeout(load, 1000);
    return;
  }
  if (answered) return;
  if (cut) { cut = false; status(""); }
  const q = await r.json().catch(() => ({}));
  if (!r.ok) {
    $("q-wait").hidden = true;
    if (q.spent === "answered") {  // sent already (a reload after sending): thanked, not an error
      $("q-form").innerHTML = ""; status("Thank you! Your answers are recorded.");
    } else if (loaded || q.spent === "closed") {  // it worked before: the questionnaire closed, not a wrong link
      $("q-form").innerHTML = ""; status("The questionnaire is closed. Thank you!");
    }
    else status(q.error || "this link does not work", true);
    return;
  }
  loaded = true;
  if (!q.ready) { $("q-wait").hidden = false; setTimeout(load, 300); return; }
  $("q-wait").hidden = true;
  if (!built) { build(q); built = true; }
  setTimeout(load, 1000);
}
load();
