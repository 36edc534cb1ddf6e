// mcit: wheel zoom about the cursor. viser's camera controls zoom towards the centre of the view;
// this takes the wheel over the 3D canvas and sends (cursor x, y in 0..1 of the canvas, deltaY, n)
// to the server through a hidden text field labelled "mcit-wheel"; the server moves the camera so
// that the point under the cursor stays under it (app/ui/client.py, ClientPanel._on_wheel).
// It also tells the server of double clicks on the video, and gives the keyboard back to the page's
// shortcuts after a chooser or a number box is used (see below).
(function () {
  if (window.__mcitWheel) return;
  window.__mcitWheel = true;
  var n = 0, pending = null, timer = null;
  function field(label) {
    label = label || "mcit-wheel";
    var labels = document.querySelectorAll("p");
    for (var i = 0; i < labels.length; i++) {
      if (labels[i].textContent === label) {
        var row = labels[i].parentElement && labels[i].parentElement.parentElement;
        var box = row && row.parentElement;
        if (box && box.style.display !== "none") box.style.display = "none";
        return row ? row.querySelector("input") : null;
      }
    }
    return null;
  }
  function write(input, text) { // as if typed: the panel sends it to the server
    var setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set;
    setter.call(input, text);
    input.dispatchEvent(new Event("input", { bubbles: true }));
  }
  function send() {
    timer = null;
    var input = field();
    if (!input || !pending) return;
    n += 1;
    write(input, pending.x.toFixed(5) + " " + pending.y.toFixed(5) + " " + pending.dy.toFixed(2) + " " + n);
    pending = null;
  }
  function view(e) { // the 3D view's canvas rectangle, when the event is on it; else null
    var t = e.target;
    if (!t || t.tagName !== "CANVAS") return null;
    var r = t.getBoundingClientRect();
    return r.width < 200 || r.height < 200 ? null : r;
  }
  window.addEventListener("wheel", function (e) {
    var r = view(e);
    if (!r) return; // not the 3D view
    if (!field()) return; // no mcit panel: leave the wheel to the viewer
    e.preventDefault();
    e.stopPropagation();
    var dy = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaY;
    var x = (e.clientX - r.left) / r.width, y = (e.clientY - r.top) / r.height;
    pending = pending ? { x: x, y: y, dy: pending.dy + dy } : { x: x, y: y, dy: dy };
    if (timer === null) timer = setTimeout(send, 16); // at most one update a frame
  }, { capture: true, passive: false });
  // The 3D view's size on screen (CSS pixels), told through the hidden field "mcit-canvas" as "width height" when it
  // changes: viser reports its camera's image in the canvas's own pixels, which are the screen's times the page's
  // pixel ratio (2 on many laptops, less when viser lowers it for speed), and the server's radii (how near a click
  // picks an object or a corner) are in the screen's pixels (app/ui/viewport.py, Viewport.on_canvas_size).
  function tellSize() {
    var input = field("mcit-canvas");
    if (!input) return;
    var best = null, canvases = document.querySelectorAll("canvas");
    for (var i = 0; i < canvases.length; i++) {
      var r = canvases[i].getBoundingClientRect();
      if (r.width >= 200 && r.height >= 200 && (!best || r.width * r.height > best.width * best.height)) best = r;
    }
    if (!best) return;
    // told again whenever the field does not hold it: a panel made anew (viser reconnected) has an empty field
    var said = Math.round(best.width) + " " + Math.round(best.height);
    if (input.value !== said) write(input, said);
  }
  setInterval(function () { field(); field("mcit-dblclick"); }, 1000); // keep the fields hidden when the panel re-renders
  setInterval(tellSize, 250); // the view changes size with the window and the docked panel, not only on "resize"

  // Double clicks on the video are told here, from the presses' own timestamps (e.timeStamp): the
  // server cannot time them, since a busy page, network or server delays one click's message more
  // than the other's (0.3-2.7 s apart at the server for a double click on a loaded machine, which then
  // read it as two clicks). The first press is an ordinary click; the second press of a double click
  // is kept from the viewer, and sent as "x y n" (x, y in 0..1 of the canvas) through the hidden field
  // "mcit-dblclick" (app/ui/client.py, ClientPanel._on_double).
  var DOUBLE_MS = 500, DOUBLE_PX = 5; // the usual desktop double click (500 ms), a steady hand
  var down = null, lastUp = null, swallowed = null, nd = 0;
  window.addEventListener("pointerdown", function (e) {
    var r = view(e);
    if (!r || e.button !== 0 || !field("mcit-dblclick")) { down = lastUp = null; return; }
    if (lastUp && e.timeStamp - lastUp.t <= DOUBLE_MS && Math.hypot(e.clientX - lastUp.x, e.clientY - lastUp.y) <= DOUBLE_PX) {
      swallowed = { id: e.pointerId, x: (e.clientX - r.left) / r.width, y: (e.clientY - r.top) / r.height };
      down = lastUp = null;
      e.stopPropagation();
      e.preventDefault();
      return;
    }
    down = { x: e.clientX, y: e.clientY };
  }, true);
  window.addEventListener("pointerup", function (e) {
    if (swallowed && e.pointerId === swallowed.id) {
      var input = field("mcit-dblclick"), s = swallowed;
      swallowed = null;
      e.stopPropagation();
      e.preventDefault();
      nd += 1;
      // told 50 ms on: viser sends the first click through a 20 ms throttle, so a quick double click (a
      // script's, 1 ms apart) was told before its own first click, which the server then took as a new one
      var said = s.x.toFixed(5) + " " + s.y.toFixed(5) + " " + nd;
      if (input) setTimeout(function () { write(input, said); }, 50);
      return;
    }
    // a press on the video released where it was pressed (not a drag) may start a double click (the
    // release's target is the viewer's overlay, not the canvas)
    var still = down && e.button === 0 && Math.hypot(e.clientX - down.x, e.clientY - down.y) <= DOUBLE_PX;
    lastUp = still ? { t: e.timeStamp, x: e.clientX, y: e.clientY } : null;
    down = null;
  }, true);

  // Choosers give the keys back: a chooser (Mantine Select) keeps the keyboard after an option is
  // picked, so the next shortcut (Z: Undo change, R: Solve) was typed into it instead. Once an option
  // is picked the chooser lets go of the keyboard; a key pressed in a closed chooser goes to the
  // page's shortcuts instead.
  function chooserInput(el) {
    return el && el.tagName === "INPUT" && el.closest && el.closest(".mantine-Select-root, [class*='Select-root']") ? el : null;
  }
  document.addEventListener("click", function (e) {
    var opt = e.target && e.target.closest && e.target.closest("[role='option']");
    if (!opt) return;
    setTimeout(function () {
      var input = chooserInput(document.activeElement);
      if (input) input.blur();
    }, 0);
  }, true);
  document.addEventListener("keydown", function (e) {
    var input = chooserInput(e.target);
    if (!input || input.getAttribute("aria-expanded") === "true") return; // an open list: its own keys
    if (e.key.length !== 1 && e.key !== "Enter" && e.key !== "Escape" && e.key !== "Backspace") return;
    if (e.key === "Enter" || e.key === "Escape") { if (e.isTrusted === false) return; }
    e.preventDefault();
    e.stopPropagation();
    input.blur();
    document.body.dispatchEvent(new KeyboardEvent("keydown", {
      key: e.key, code: e.code, keyCode: e.keyCode, which: e.which, shiftKey: e.shiftKey, ctrlKey: e.ctrlKey,
      altKey: e.altKey, metaKey: e.metaKey, bubbles: true, cancelable: true }));
  }, true);

  // A number typed in a box (Seconds back) kept the keyboard: Backspace and F then went into the box,
  // not to Remove last and Freeze (a new operator's run). Enter in such a box, or a click on the video,
  // gives the keyboard back to the page's shortcuts.
  function textInput(el) {
    return el && (el.tagName === "INPUT" || el.tagName === "TEXTAREA") && !chooserInput(el) ? el : null;
  }
  document.addEventListener("pointerdown", function (e) {
    if (!e.target || e.target.tagName !== "CANVAS") return;
    var input = textInput(document.activeElement);
    if (input) input.blur();
  }, true);
  document.addEventListener("keyup", function (e) {
    var input = textInput(e.target);
    if (input && e.key === "Enter") input.blur();
  }, true);
})();
