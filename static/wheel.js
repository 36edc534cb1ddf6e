// mcit: wheel zoom about the cursor. viser's camera controls zoom towards the centre of the view;
// this takes the wheel over the 3D canvas and sends (cursor x, y in 0..1 of the canvas, deltaY, n)
// to the server through a hidden text field labelled "mcit-wheel"; the server moves the camera so
// that the point under the cursor stays under it (app/ui/client.py, ClientPanel._on_wheel).
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
})();
