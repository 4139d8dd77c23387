// What every lab page shares: the session and token from the URL, the tab's client id,
// and a WebSocket that reconnects and asks for the whole view again (hub.py).
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

  function connect(page, handlers) {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const url = () => `${proto}//${location.host}/s/${encodeURIComponent(session)}/ws?t=${encodeURIComponent(token)}` +
      `&page=${page}&client=${client}`;
    const link = { ws: null, open: false, connects: 0, pings: new Map(), client };
    let delay = 200;
    function open() {
      const ws = new WebSocket(url());
      link.ws = ws;
      ws.onopen = () => { link.open = true; link.connects += 1; delay = 200; handlers.onLink(true); };
      ws.onmessage = (m) => {
        let msg;
        try { msg = JSON.parse(m.data); } catch (e) { return; }
        if (msg.type === "state") handlers.onState(msg.state, msg.role);
        else if (msg.type === "rejected") handlers.onRejected && handlers.onRejected(msg);
        else if (msg.type === "pong") {
          const done = link.pings.get(msg.t);
          if (done) { link.pings.delete(msg.t); done({ rtt: performance.now() - msg.t, sent: msg.t, server_ns: msg.server_ns }); }
        }
      };
      ws.onclose = (ev) => {
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
    // true only if the message went out: a socket that is closing (before its onclose) drops what it is given
    // without a word, so "open" is the socket's own state, not only ours
    link.up = () => link.open && link.ws.readyState === WebSocket.OPEN;
    link.send = (obj) => { if (link.up()) { link.ws.send(JSON.stringify(obj)); return true; } return false; };
    // the raw WebSocket round trip: {rtt (ms), sent (performance.now()), server_ns (the server's clock)}
    link.ping = () => new Promise((resolve) => {
      const t = performance.now();
      link.pings.set(t, resolve);
      link.send({ type: "ping", t });
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
