"""viser's pose setters without np.allclose: the same test, so the same messages."""

from __future__ import annotations

import numpy as np

from app.ui.viser_hints import close_as_numpy, plain_pose_setter


def test_close_as_numpy_agrees_with_allclose_on_near_equal_huge_and_non_finite_values():
    rng = np.random.default_rng(0)
    special = [0.0, -0.0, 1e-9, 1e-7, 1.0, 1.0 + 1e-6, 1.0 + 2e-5, 1e300, np.inf, -np.inf, np.nan]
    cases = 0
    for _ in range(3000):
        old = rng.choice(special, 3) if rng.random() < 0.5 else rng.normal(size=3) * 10.0 ** rng.integers(-9, 9)
        kind = rng.integers(4)
        with np.errstate(invalid="ignore", over="ignore"):
            new = old + (
                rng.normal(size=3) * np.abs(old) * 10.0 ** rng.uniform(-8, -3)
                if kind == 0
                else rng.normal(size=3) * 10.0 ** rng.uniform(-10, -6)
                if kind == 1
                else rng.choice(special, 3)
                if kind == 2
                else 0.0
            )
        with np.errstate(invalid="ignore"):
            want = bool(np.allclose(new, old))
        assert close_as_numpy(tuple(map(float, new)), old) == want, (new, old)
        cases += want
    assert 300 < cases < 2700  # both answers met many times


def test_a_label_moved_is_sent_and_one_not_moved_is_not():
    import viser

    from tests.e2e.harness import free_port

    assert plain_pose_setter() and plain_pose_setter()  # applied, and once only
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        label = server.scene.add_label("/l", "a", position=(1.0, 2.0, 3.0))
        buffer = server._websock_server.get_message_buffer()
        sent = buffer.message_counter
        label.position = (1.0, 2.0, 3.0 + 1e-9)  # within allclose: nothing sent
        assert buffer.message_counter == sent and tuple(label.position) == (1.0, 2.0, 3.0)
        label.position = (1.0, 2.5, 3.0)
        assert buffer.message_counter == sent + 1 and tuple(label.position) == (1.0, 2.5, 3.0)
        label.wxyz = (0.0, 1.0, 0.0, 0.0)
        assert buffer.message_counter == sent + 2 and tuple(label.wxyz) == (0.0, 1.0, 0.0, 0.0)
    finally:
        server.stop()
