"""A frame's oriented edges prepared ahead (as the interface does when Update pose freezes a frame)
are the ones auto match then reads: the same object, every bin's tree built, the same distances."""

from __future__ import annotations

import numpy as np

from app.vision import evaluate


def test_prepared_frame_is_found_ready_with_the_same_distances():
    rng = np.random.default_rng(0)
    img = np.zeros((120, 160), np.uint8)
    img[30:90, 40:120] = 200  # a bright rectangle: edges in two orientations
    img = np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8)
    with evaluate._CACHE_LOCK:
        evaluate._CACHE.clear()
    fresh = evaluate.oriented_edges(img)
    u, v = rng.uniform(0, 159, 50), rng.uniform(0, 119, 50)
    expected = [fresh.distance(b, u, v, 10.0) for b in range(len(fresh))]
    with evaluate._CACHE_LOCK:
        evaluate._CACHE.clear()
    evaluate.prepare_frame(img)
    ready = evaluate.oriented_edges(img.copy())  # same contents: the prepared one
    assert len(ready._trees) == len(ready)  # every bin's tree built ahead
    for b in range(len(ready)):
        assert np.array_equal(ready.distance(b, u, v, 10.0), expected[b])
