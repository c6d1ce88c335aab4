import torch

from intermask.interm.blocks import AdaLNModulation, InterMBlock, SpatioTemporalLayer

ROWS, STEPS, WIDTH = 5, 3, 16


def _inputs(batch: int = 2):
    torch.manual_seed(0)
    n = ROWS * STEPS
    x = torch.randn(batch, 2 * n + 1, WIDTH)
    c = torch.randn(batch, WIDTH)
    padding = torch.zeros(batch, 2 * n + 1, dtype=torch.bool)
    padding[0, n - 2 : n] = True
    return x, c, padding


def _block(**flags: bool) -> InterMBlock:
    torch.manual_seed(0)
    return InterMBlock(width=WIDTH, heads=4, ff=24, dropout=0.0, **flags).eval()


def test_modulation_is_zero_at_initialisation():
    chunks = AdaLNModulation(width=WIDTH, chunks=3)(torch.randn(4, WIDTH))
    assert len(chunks) == 3 and all(torch.equal(ch, torch.zeros(4, WIDTH)) for ch in chunks)


def test_adaln_zero_block_is_the_identity_at_initialisation():
    x, c, padding = _inputs()
    assert torch.equal(_block()(x, c, padding, rows=ROWS), x)


def test_block_is_not_the_identity_once_gates_open(randomize):
    x, c, padding = _inputs()
    block = _block()
    randomize(block)
    assert not torch.allclose(block(x, c, padding, rows=ROWS), x)


def test_double_residual_quirk_counts_the_input_twice():
    torch.manual_seed(0)
    x, c = torch.randn(2, ROWS * STEPS, WIDTH), torch.randn(2, WIDTH)
    padding = torch.zeros(2, ROWS * STEPS, dtype=torch.bool)
    correct = SpatioTemporalLayer(width=WIDTH, heads=4, dropout=0.0)
    quirk = SpatioTemporalLayer(width=WIDTH, heads=4, dropout=0.0, double_residual_quirk=True)
    assert torch.equal(correct(x, c, padding, rows=ROWS), x)
    assert torch.equal(quirk(x, c, padding, rows=ROWS), 2 * x)


def test_swapping_persons_in_a_block_swaps_the_outputs(randomize):
    x, c, padding = _inputs()
    block = _block()
    randomize(block)
    n = ROWS * STEPS
    a, sep, b = x.split([n, 1, n], dim=1)
    pa, ps, pb = padding.split([n, 1, n], dim=1)
    out = block(x, c, padding, rows=ROWS)
    swapped = block(torch.cat([b, sep, a], 1), c, torch.cat([pb, ps, pa], 1), rows=ROWS)
    oa, osep, ob = out.split([n, 1, n], dim=1)
    torch.testing.assert_close(swapped, torch.cat([ob, osep, oa], 1), atol=1e-5, rtol=1e-5)


def test_cross_context_quirk_changes_the_output(randomize):
    x, c, padding = _inputs()
    paper, quirk = _block(), _block(cross_context_quirk=True)
    randomize(paper)
    quirk.load_state_dict(paper.state_dict())
    assert not torch.allclose(paper(x, c, padding, rows=ROWS), quirk(x, c, padding, rows=ROWS))
