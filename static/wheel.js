// mcit: wheel zoom about the cursor. viser's camera controls zoom towards the centre of the view;
// this takes the wheel over the 3D canvas and sends (cursor x, y in 0..1 of the canvas, deltaY, n)
// to the server through a hidden text field labelled "mcit-wheel"; the server moves the camera so
// that the point under the cursor stays under it (app/ui/client.py, ClientPanel._on_wheel).
// It also gives the keyboard back to the page's shortcuts after a chooser is used (see below).
(function () {
  if (window.__mcitWheel) return;
  window.__mcitWheel = true;
  var n = 0, pending = null, timer = null;
  function field() {
    var labels = document.querySelectorAll("p");
    for (var i = 0; i < labels.length; i++) {
      if (labels[i].textContent === "mcit-wheel") {
        var row = labels[i].parentElement && labels[i].parentElement.parentElement;
        var box = row && row.parentElement;
        if (box && box.style.display !== "none") box.style.display = "none";
        return row ? row.querySelector("input") : null;
      }
    }
    return null;
  }
  function send() {
    timer = null;
    var input = field();
    if (!input || !pending) return;
    var setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set;
    n += 1;
    setter.call(input, pending.x.toFixed(5) + " " + pending.y.toFixed(5) + " " + pending.dy.toFixed(2) + " " + n);
    input.dispatchEvent(new Event("input", { bubbles: true }));
    pending = null;
  }
  window.addEventListener("wheel", function (e) {
    var t = e.target;
    if (!t || t.tagName !== "CANVAS") return;
    var r = t.getBoundingClientRect();
    if (r.width < 200 || r.height < 200) return; // not the 3D view
    if (!field()) return; // no mcit panel: leave the wheel to the viewer
    e.preventDefault();
    e.stopPropagation();
    var dy = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaY;
    var x = (e.clientX - r.left) / r.width, y = (e.clientY - r.top) / r.height;
    pending = pending ? { x: x, y: y, dy: pending.dy + dy } : { x: x, y: y, dy: dy };
    if (timer === null) timer = setTimeout(send, 16); // at most one update a frame
  }, { capture: true, passive: false });
  setInterval(field, 1000); // keep the field hidden when the panel re-renders

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
