// One WebSocket to the bridge that reconnects by itself (the tablet's Wi-Fi may drop) and
// hands every JSON message from the bridge to the page.
"use strict";
function connectSocket(path, onMessage, onStatus) {
  let ws = null;
  let delay = 500;
  function open() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    ws = new WebSocket(scheme + location.host + path);
    ws.onopen = () => { delay = 500; onStatus(true); };
    ws.onmessage = (event) => {
      let message;
      try { message = JSON.parse(event.data); } catch (e) { return; }
      onMessage(message);
    };
    ws.onclose = () => {
      onStatus(false);
      setTimeout(open, delay);
      delay = Math.min(delay * 2, 5000);
    };
  }
  open();
  return {
    send(message) {
      if (ws && ws.readyState === WebSocket.OPEN) {
        ws.send(JSON.stringify(message));
        return true;
      }
      return false;
    },
  };
}
