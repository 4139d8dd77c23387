// What every lab page shares: the session and token from the URL, the tab's client id,
// and a WebSocket that reconnects and asks for the whole view again (hub.py).
// Heartbeat rule: the page pings every BEAT_MS; a ping that nothing from the server has followed within
// DEADLINE_MS means the socket is down even though it did not close (a Wi-Fi drop leaves TCP half-open and
// the browser holds what the page sends, to deliver it when the network is back: trial29 F7). The page then
// abandons that socket, says so (onLink(false)), takes no input, and opens a new one until it connects.
// The page pings, not the server: only the page can stop taking touches, and a browser answers the server's
// protocol pings (uvicorn's ws_ping_interval) without telling the page.
// Clock rule (trial32 G): the hub times a touch by the page's clock (performance.now()), which stops while the
// device sleeps. A page that may have slept opens a new socket (a fresh baseline for the hub's late rule, and
// a socket known to be alive): when it comes back after DEADLINE_MS or more hidden, frozen or away
// (visibilitychange, resume, pageshow; timed by Date.now(), which does tick during sleep), when its clock fell
// behind the wall clock by BEAT_MS or more since the last beat (it slept while visible), and when the hub
// refused a touch as late on this socket ("late": true).
"use strict";
(function () {
  const parts = location.pathname.split("/");  // /s/<session>/<page>
  const session = decodeURIComponent(parts[2] || "");
  const token = new URLSearchParams(location.search).get("t") || "";
  const fresh = () => {
    const id = Array.from(crypto.getRandomValues(new Uint8Array(12)), b => b.toString(16).padStart(2, "0")).join("");
    sessionStorage.setItem("pairplay-client", id);
    return id;
  };
  let client = sessionStorage.getItem("pairplay-client") || fresh();  // one per tab, kept across reloads
  const now = () => performance.timeOrigin + performance.now();  // the page's clock, ms
  // a few seconds: well above a lab network's round trip (1-20 ms) and a loaded server's answer, short enough
  // that a touch made after a drop is dropped; a throttled timer (a hidden tab) only checks later, never early
  const BEAT_MS = 1000, DEADLINE_MS = 3000;

  function connect(page, handlers) {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const url = () => `${proto}//${location.host}/s/${encodeURIComponent(session)}/ws?t=${encodeURIComponent(token)}` +
      `&page=${page}&client=${client}`;
    // lost: sockets the heartbeat gave up; renewed: why a live socket was replaced by a new one (the clock rule)
    const link = { ws: null, open: false, connects: 0, lost: 0, renewed: [], pings: new Map(), client };
    let delay = 200;
    let beatSent = -1, heard = -1;  // performance.now() of the last heartbeat ping, of the last message heard
    function open() {
      const ws = new WebSocket(url());
      link.ws = ws;
      ws.onopen = () => {
        link.open = true; link.connects += 1; delay = 200; beatSent = -1; heard = performance.now();
        handlers.onLink(true);
        beat();
      };
      ws.onmessage = (m) => {
        heard = performance.now();
        let msg;
        try { msg = JSON.parse(m.data); } catch (e) { return; }
        if (msg.type === "state") handlers.onState(msg.state, msg.role);
        else if (msg.type === "rejected") {
          if (handlers.onRejected) handlers.onRejected(msg);
          if (msg.late) renew("late");  // this socket's baseline is wrong for this page's clock: a new one
        }
        else if (msg.type === "pong") {
          const done = link.pings.get(msg.t);
          if (done) { link.pings.delete(msg.t); done({ rtt: performance.now() - msg.t, sent: msg.t, server_ns: msg.server_ns }); }
        }
      };
      ws.onclose = (ev) => {
        if (ws !== link.ws) return;  // a socket the heartbeat abandoned: its late close says nothing
        link.open = false;
        handlers.onLink(false, ev.code);
        if (ev.code === 4403) return;  // refused: wrong token; retrying will not help
        if (ev.code === 4000) {
          // REPLACED (hub.py): a newer page came with this tab's id while this one is alive, so it is not
          // this tab reloading but a twin (a duplicated tab copies sessionStorage). Coming back with the
          // same id would evict the twin, which would evict us: a reconnect war. This page takes a fresh id
          // and comes back as another tab (read-only while the twin plays).
          client = fresh();
          link.client = client;
          window.pairplayLab.client = client;
          setTimeout(open, 0);
          return;
        }
        setTimeout(open, delay);
        delay = Math.min(delay * 2, 2000);
      };
    }
    // the heartbeat (see the rule at the top): a new ping only once the last one was answered (or anything
    // came after it), so a page never piles pings into a socket that holds them
    let behind = Date.now() - now();  // how far the page's clock is behind the wall clock (the clock rule)
    function beat() {
      const lag = Date.now() - now();
      const slept = lag - behind >= BEAT_MS;
      behind = lag;
      if (!link.up()) return;
      if (slept) { renew("slept"); return; }
      const t = performance.now();
      if (beatSent >= 0 && heard < beatSent) {
        if (t - beatSent > DEADLINE_MS) { link.lost += 1; abandon(); }
        return;
      }
      beatSent = t;
      link.ws.send(JSON.stringify({ type: "ping", t, page_ms: now() }));
    }
    function abandon() {
      // the socket is abandoned, not waited for: its close handshake cannot pass a dead network either. Its
      // handlers go, so nothing it delivers late is taken; what it holds may still arrive, and the hub refuses
      // a touch that comes later than this deadline allows (hub.py LATE_MS)
      const ws = link.ws;
      link.ws = null;
      link.open = false;
      ws.onopen = ws.onmessage = null;
      try { ws.close(); } catch (e) { /* closing a dead socket: nothing to do */ }
      handlers.onLink(false, 0);
      open();
    }
    // a live socket replaced by a new one (the clock rule): the page says "Reconnecting…" meanwhile; the hub
    // takes the new socket with this tab's id for a reload, so the page keeps its seat
    function renew(why) {
      if (!link.up()) return;  // not connected: the socket being opened starts fresh anyway
      link.renewed.push(why);
      abandon();
    }
    setInterval(beat, BEAT_MS);
    // hidden, frozen or away since (Date.now(), null: here): the device may have slept meanwhile
    let awaySince = null;
    const away = () => { if (awaySince === null) awaySince = Date.now(); };
    const back = () => {
      if (awaySince === null) return;
      const gone = Date.now() - awaySince;
      awaySince = null;
      behind = Date.now() - now();  // said here: the next beat need not say it again
      if (gone >= DEADLINE_MS) renew("woke");
    };
    document.addEventListener("visibilitychange", () => (document.hidden ? away() : back()));
    document.addEventListener("freeze", away);
    document.addEventListener("resume", back);
    window.addEventListener("pagehide", away);
    window.addEventListener("pageshow", back);
    // true only if the message went out: a socket that is closing (before its onclose) drops what it is given
    // without a word, so "open" is the socket's own state, not only ours
    link.up = () => link.open && !!link.ws && link.ws.readyState === WebSocket.OPEN;
    link.send = (obj) => { if (link.up()) { link.ws.send(JSON.stringify(obj)); return true; } return false; };
    // the raw WebSocket round trip: {rtt (ms), sent (performance.now()), server_ns (the server's clock)}
    link.ping = () => new Promise((resolve) => {
      const t = performance.now();
      link.pings.set(t, resolve);
      link.send({ type: "ping", t, page_ms: now() });
    });
    open();
    return link;
  }
  function el(tag, cls, text) {
    const e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  }
  window.pairplayLab = { session, token, client, now, connect, el };
})();
