"""A Function streamed over columns a block at a time (nlp_calib.solvers.blocks.stream)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from nlp_calib.solvers.backends.base import INTERPRETED
from nlp_calib.solvers.blocks import BLOCK, stream


def _function() -> ca.Function:
    x = ca.SX.sym("x", 2)
    k = ca.SX.sym("k")
    return ca.Function(
        "f", [x, k], [ca.vertcat(k * x[0] * x[1], x[0] - x[1]), ca.horzcat(x, 2 * x)], ["x", "k"], ["a", "b"]
    )


def test_every_block_is_the_map_and_the_last_shorter_block_holds_no_arrays_of_its_own() -> None:
    """Each block's outputs are CasADi's map over its columns; the last block, shorter than the
    others, writes the first columns of the arrays the others wrote (one set of arrays held: a
    set of its own was as large again as a block's outputs, at the stream's end)."""
    f = _function()
    n = 2 * BLOCK + 1000
    x = np.asfortranarray(np.random.default_rng(0).standard_normal((2, n)))
    seen = []
    for w, (a, b) in stream(INTERPRETED, f, {"x": x}, {"k": 1.5}, n):
        want_a, want_b = (np.asarray(v) for v in f.map(w.stop - w.start)(x[:, w], 1.5))
        assert np.array_equal(a, want_a) and np.array_equal(b, want_b)
        seen.append((w.stop - w.start, a, b))
    (_, first_a, first_b), (size, last_a, last_b) = seen[0], seen[-1]
    assert size == 1000 and last_a.shape == (2, 1000) and last_b.shape == (2, 2 * 1000)
    assert np.shares_memory(first_a, last_a) and np.shares_memory(first_b, last_b)
