"""The training loss through unseen.testing (SPEC.md §13, §14.1): the oracle's binding, seven
seeded wrong ports (each must fail, and be named on nearly every seed from its value, its
SSIM map or its gradient), torch ports made wrong apart from the emulations, and real
third-party SSIMs under their conventions — INRIA's formula in torch (zero padding, with
its map and gradient), pytorch-msssim (valid) and torchmetrics (reflect, with its full
image) — on 20 seeds of ``loss_case``, each failing under another convention with that
convention named. The torch-based ports are
skipped, with the reason printed, where their package is not installed.
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)


def test_the_oracle_binding_and_its_conventions():
    case = ut.loss_case(0)
    x, y = case["x"], case["y"]
    for conv in ut.LOSS_CONVENTIONS:
        out = unseen.ssim(x, y, conventions=conv)
        assert abs(out["ssim"] - ut.ssim_reference(x, y, conventions=conv)) < 1e-9, conv
        assert abs(out["ssim"] - out["map"].mean()) < 1e-12, conv
    assert unseen.ssim(x, y, conventions="valid")["map"].shape == (x.shape[0] - 10, x.shape[1] - 10)
    assert unseen.ssim(x, x)["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert unseen.ssim(x, y)["l1"] == pytest.approx(float(np.abs(x - y).astype(np.float64).mean()))
    with pytest.raises(ValueError, match="conventions"):
        unseen.ssim(x, y, conventions="same")
    with pytest.raises(ValueError, match="larger than 10x10"):
        unseen.ssim(x[:8, :8].copy(), y[:8, :8].copy(), conventions="reflect")
    with pytest.raises(ValueError, match="y: expected"):
        unseen.ssim(x, y[:, :, :2].copy())


@pytest.mark.parametrize("mistake, evidence", [
    (m.name, e) for m in ut.LOSS_MISTAKES for e in ("value", "map", "grad")
    if (m.name, e) != ("no_dssim", "map")])  # SSIM added instead of 1 − SSIM: the map is right
def test_wrong_ports_fail_with_their_mistake_named(mistake, evidence):
    text = next(m.text for m in ut.LOSS_MISTAKES if m.name == mistake)

    def port(x, y):
        o = unseen.ssim(x, y)
        if evidence == "grad":
            return {"grad": ut.loss_gradient_reference(x, y, mistake=mistake)}
        if evidence == "map":
            return {"map": ut.ssim_map_reference(x, y, mistake=mistake)}
        if mistake == "no_dssim":
            return {"loss": 0.8 * o["l1"] + 0.2 * o["ssim"]}
        s = ut.ssim_reference(x, y, mistake=mistake)
        return {"ssim": s, "loss": 0.8 * o["l1"] + 0.2 * (1 - s)}

    named = 0
    for seed in range(12):
        r = ut.compare_loss(port, seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        assert r.cause in ("", text), f"seed {seed}: another cause named: {r.message()}"
        named += r.cause == text
    assert named >= 11, f"named on {named} of 12"  # measured: 12 of 12


def _torch():
    return pytest.importorskip("torch", reason="torch is not installed "
                               "(python/requirements-port.txt)")


def _inria_port(taps=11, sigma=1.5, c1=1e-4, c2=9e-4, luma=False, give=None):
    """INRIA's loss_utils formula in float32 (2D Gaussian window, zero padding), returning
    ``give`` of ssim, map, l1, loss and grad (all by default); the arguments make it wrong
    the way a port might, written apart from the harness's emulations: the window's taps
    and σ, the constants, SSIM of the luma (Rec. 601 weights) instead of per channel."""
    torch = _torch()
    F = torch.nn.functional

    def to(a):
        return torch.from_numpy(a).permute(2, 0, 1)[None]

    def port(x, y):
        t = torch.arange(taps, dtype=torch.float32) - taps // 2
        g = torch.exp(-t * t / (2 * sigma * sigma))
        g = g / g.sum()
        a, b = to(x).clone().requires_grad_(True), to(y)
        u, v = a, b
        if luma:
            wl = torch.tensor([0.299, 0.587, 0.114]).view(1, 3, 1, 1)
            u, v = (a * wl).sum(1, keepdim=True), (b * wl).sum(1, keepdim=True)
        ch = u.shape[1]
        w = (g[:, None] @ g[None, :]).expand(ch, 1, taps, taps).contiguous()
        blur = lambda q: F.conv2d(q, w, padding=taps // 2, groups=ch)  # noqa: E731
        m1, m2 = blur(u), blur(v)
        s11, s22, s12 = blur(u * u) - m1 ** 2, blur(v * v) - m2 ** 2, blur(u * v) - m1 * m2
        ssim_map = (((2 * m1 * m2 + c1) * (2 * s12 + c2))
                    / ((m1 ** 2 + m2 ** 2 + c1) * (s11 + s22 + c2)))
        ssim = ssim_map.mean()
        l1 = (a - b).abs().mean()
        loss = 0.8 * l1 + 0.2 * (1 - ssim)
        (grad,) = torch.autograd.grad(loss, a)
        out = {"ssim": ssim.item(), "l1": l1.item(), "loss": loss.item(),
               "map": ssim_map[0].detach().permute(1, 2, 0).numpy(),
               "grad": grad[0].permute(1, 2, 0).numpy()}
        return out if give is None else {k: out[k] for k in give}

    return port


def _msssim_port():
    _torch()
    ms = pytest.importorskip("pytorch_msssim", reason="pytorch-msssim is not installed "
                             "(python/requirements-port.txt)")
    import torch

    to = lambda a: torch.from_numpy(a).permute(2, 0, 1)[None]  # noqa: E731
    return lambda x, y: {"ssim": ms.ssim(to(x), to(y), data_range=1.0).item()}


def _torchmetrics_port():
    _torch()
    tm = pytest.importorskip("torchmetrics.functional.image", reason="torchmetrics is not "
                             "installed (python/requirements-port.txt)")
    import torch

    to = lambda a: torch.from_numpy(a).permute(2, 0, 1)[None]  # noqa: E731

    def port(x, y):
        ssim, full = tm.structural_similarity_index_measure(to(x), to(y), data_range=1.0,
                                                            return_full_image=True)
        return {"ssim": ssim.item(), "map": full[0].permute(1, 2, 0).numpy()}

    return port


@pytest.mark.parametrize("make, conventions", [(_inria_port, "inria"),
                                               (_msssim_port, "valid"),
                                               (_torchmetrics_port, "reflect")],
                         ids=["inria-torch", "pytorch-msssim", "torchmetrics"])
def test_third_party_ssim_passes_under_its_convention(make, conventions):
    port = make()
    for seed in SEEDS:
        r = ut.compare_loss(port, seed=seed, conventions=conventions)
        assert r.ok, f"seed {seed}: {r.message()}"
    other = "valid" if conventions == "inria" else "inria"
    r = ut.compare_loss(port, seed=0, conventions=other)
    assert not r.ok and r.cause == f"the {conventions!r} SSIM convention", r.message()


def test_wrong_loss_gradients_fail():
    """The gradient of INRIA's loss: L1 averaged per pixel instead of per value (3× too
    large), or the D-SSIM term's sign flipped, fails; the oracle's own passes."""
    for seed in range(4):
        c = ut.loss_case(seed)
        o = unseen.ssim(c["x"], c["y"], gradient=True)
        n = c["x"].size
        l1 = 0.8 * np.sign(c["x"] - c["y"]) / n
        for name, grad in (("per pixel", o["grad_loss"] + 2 * l1),
                           ("sign", 2 * l1 - o["grad_loss"])):
            r = ut.compare_loss(lambda x, y, g=grad: {"grad": g}, c)
            assert not r.ok and "grad" in r.message(), f"{name}: {r.message()}"
        assert ut.compare_loss(lambda x, y: {"grad": o["grad_loss"]}, c).ok
    with pytest.raises(ValueError, match="only for conventions 'inria'"):
        unseen.ssim(c["x"], c["y"], conventions="valid", gradient=True)


@pytest.mark.parametrize("give", [("ssim",), ("loss",), ("map",), ("grad",)])
def test_independent_wrong_ports_are_named_from_any_evidence_or_not_at_all(give):
    """Torch ports made wrong apart from the emulations: two listed mistakes (unsquared
    constants, a box window as σ → ∞) are named from each piece of evidence alone; two
    unlisted ones (a 7-tap window, SSIM of the luma) fail and are never given a wrong name:
    judged on one number they once were ("the 'reflect' convention"); a hypothesis now
    names one number only by reproducing it within the tolerance."""
    listed = {m.name: m.text for m in ut.LOSS_MISTAKES}
    ports = [(dict(c1=0.01, c2=0.03), listed["unsquared_constants"]),
             (dict(sigma=1e6), listed["box_window"]),
             (dict(taps=7), ""), (dict(luma=True), "")]
    for kwargs, text in ports:
        port = _inria_port(give=give, **kwargs)
        for seed in range(8):
            r = ut.compare_loss(port, seed=seed)
            assert not r.ok, f"{kwargs}, seed {seed}: the mistake passed"
            assert r.cause == text, f"{kwargs}, seed {seed}: {r.message()}"


def test_library_ssim_with_a_mistake_fails_with_it_named():
    # LOSS_MISTAKES made through the libraries' own options rather than the harness's
    # emulation: pytorch-msssim (valid) and torchmetrics (reflect) on [0, 1] images told
    # their data range is 255, and with a Gaussian window of σ = 1; torchmetrics with an
    # 11×11 box window.
    _torch()
    ms = pytest.importorskip("pytorch_msssim", reason="pytorch-msssim is not installed "
                             "(python/requirements-port.txt)")
    tm = pytest.importorskip("torchmetrics.functional.image", reason="torchmetrics is not "
                             "installed (python/requirements-port.txt)")
    import torch

    to = lambda a: torch.from_numpy(a).permute(2, 0, 1)[None]  # noqa: E731
    ports = [
        ("valid", "data_range_255",
         lambda x, y: {"ssim": ms.ssim(to(x), to(y), data_range=255).item()}),
        ("valid", "sigma_1",
         lambda x, y: {"ssim": ms.ssim(to(x), to(y), data_range=1.0, win_sigma=1.0).item()}),
        ("reflect", "data_range_255", lambda x, y: {
            "ssim": tm.structural_similarity_index_measure(to(x), to(y),
                                                           data_range=255.0).item()}),
        ("reflect", "sigma_1", lambda x, y: {
            "ssim": tm.structural_similarity_index_measure(to(x), to(y), data_range=1.0,
                                                           sigma=1.0).item()}),
        ("reflect", "box_window", lambda x, y: {
            "ssim": tm.structural_similarity_index_measure(
                to(x), to(y), data_range=1.0, gaussian_kernel=False, kernel_size=11).item()}),
    ]
    for conventions, mistake, port in ports:
        text = next(m.text for m in ut.LOSS_MISTAKES if m.name == mistake)
        for seed in range(6):
            r = ut.compare_loss(port, seed=seed, conventions=conventions)
            assert not r.ok, f"{conventions} {mistake}, seed {seed}: the mistake passed"
            assert r.cause == text, f"{conventions} {mistake}, seed {seed}: {r.message()}"
