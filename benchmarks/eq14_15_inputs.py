"""Eq 14 and 15's inputs: how far each measured one is from the simulator's exact mode, and what
that does to C and c.

Run:  python benchmarks/eq14_15_inputs.py [--rig albacore] [--medium water] [--draws 400]
                                          [--recording recordings/albacore-water.mcap]

1. The rig's predominant mode, exact (an eigenvector of the model's state matrix), turned so that
   v = v1 e^{mu t} sin(wt): every input of Eq 14/15 relative to v1, and each term of Eq 14's
   quadrature bracket as N s/m of C. Eq 14/15 on it give back the rig's C and c.
2. The same mode at the gages with the rig's channel noise (white, ``daq.noise_m_s2_rms``),
   6 s of free decay after the rig's blow, amplitudes by linear least squares at the exact pole
   (mode + constant): each input's bias and scatter (in units of v1, and as a phase in rad), and
   C and c: mean, scatter and the propagated standard error of
   :mod:`ramdaq.analysis.report1836.full_damping`.
3. Each hit of ``--recording`` (made by the simulator from the same rig): its inputs (from the
   joint mode fit's amplitudes, as ``ramdaq analyze`` takes them) minus the exact ones, and
   C, c with their standard errors and their distance from the rig's in standard errors.

Everything is a Monte Carlo or a fit: CPU-bound, no timing is printed.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import fields, replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ramdaq.analysis.model.response import half_sine_response, modal_form  # noqa: E402
from ramdaq.analysis.model.rig import Rig, load_rig  # noqa: E402
from ramdaq.analysis.model.rig_modes import modes_in  # noqa: E402
from ramdaq.analysis.model.structure import build_model  # noqa: E402
from ramdaq.analysis.report1836 import full_damping as fd  # noqa: E402

INPUTS = ("gamma1", "alpha1", "gamma_b1", "gamma2", "alpha2", "v_b2", "alpha_b2", "gamma_b2")
"""Eq 14/15's inputs besides v1 (which is 1 once each is divided by it)."""


def inputs(m: fd.ModeMotions) -> dict[str, float]:
    """Each input of Eq 14/15 divided by v1 (1 = sine part, 2 = cosine part)."""
    sin, cos = m.quadrature()
    v1 = sin["v"]
    out = {}
    for name in INPUTS:
        motion, part = name[:-1], name[-1]
        out[name] = (sin if part == "1" else cos)[motion] / v1
    return out


def bracket_terms(m: fd.ModeMotions, f: float, s: fd.StockConstants) -> dict[str, float]:
    """Eq 14's quadrature bracket, term by term, as N s/m of C: 12 k_s X / (v1 w)."""
    sin, cos = m.quadrature()
    scale = 12 * s.k_s / (sin["v"] * 2 * np.pi * f)
    return {"v_b2": scale * cos["v_b"], "-h gamma2": -scale * s.h * cos["gamma"],
            "b alpha2": scale * s.b * cos["alpha"], "(l/2) alpha2": scale * s.ell / 2 * cos["alpha"],
            "(l/2) alpha_b2": scale * s.ell / 2 * cos["alpha_b"]}


def exact_mode(rig: Rig) -> tuple[fd.ModeMotions, float, float, np.ndarray, object]:
    """The predominant mode: motions, f (Hz), delta, gage accelerations after the rig's blow
    (m/s^2, complex, by channel) and the model."""
    m = build_model(rig)
    form = modal_form(m)
    k = modes_in(rig, rig.medium).predominant
    lam, q = form.eigenvalues[k], form.right[: m.n_dof, k]
    hull = rig.hull_modes

    def at_stock(attr: str) -> complex:
        return sum(getattr(h, attr) * q[3 + i] for i, h in enumerate(hull))

    motions = fd.ModeMotions(q[0], q[1], q[2], at_stock("v_b"), at_stock("alpha_b"),
                             at_stock("gamma_b"))
    blow = rig.impact
    z = form.input_vector(m.force_vector(blow.location_m, blow.direction))[k] * blow.peak_force_N
    z *= half_sine_response(form.eigenvalues[k:k + 1], blow.duration_s, np.array([blow.duration_s]))[0, 0]
    return motions, lam.imag / (2 * np.pi), -2 * np.pi * lam.real / lam.imag, 2 * z * form.gage_acc[:, k], m


def section_exact(rig: Rig) -> tuple[fd.ModeMotions, float, float, np.ndarray, object]:
    motions, f, delta, acc, m = exact_mode(rig)
    s = fd.stock_constants(rig, rig.stock.bending_length_m)
    C, c = fd.eq14_15(motions, f, delta, m.M[0, 0], m.M[1, 1], rig.rudder.Ixz_kg_m2, s)
    d = rig.active_damping
    print(f"1. exact predominant mode of {rig.name} in {rig.medium}: f = {f:.4f} Hz, delta = {delta:.5f}")
    print("   input / v1:  " + "  ".join(f"{k} {v:+.4e}" for k, v in inputs(motions).items()))
    terms = bracket_terms(motions, f, s)
    print(f"   Eq 14: -2 m_y mu = {-2 * m.M[0, 0] * (-f * delta):.5g} N s/m, bracket terms: "
          + ", ".join(f"{k} {v:+.4g}" for k, v in terms.items())
          + f" (sum {sum(terms.values()):+.4g})")
    print(f"   Eq 14 C = {C:.6g} (rig {d.C_N_s_per_m:.6g}); Eq 15 c = {c:.6g} (rig {d.c_N_m_s_per_rad:.6g})")
    return motions, f, delta, acc, m


def section_noise(rig: Rig, exact: tuple, draws: int, seconds: float = 6.0) -> None:
    motions, f, delta, acc, m = exact
    gages = m.gage_numbers
    fs, sigma = rig.daq.sample_rate_hz, rig.daq.noise_m_s2_rms
    n = int(seconds * fs)
    t = np.arange(n) / fs
    lam = complex(-f * delta, 2 * np.pi * f)
    e = np.exp(lam.real * t)
    basis = np.column_stack([e * np.cos(lam.imag * t), e * np.sin(lam.imag * t), np.ones(n)])
    pinv = np.linalg.pinv(basis)
    clean = np.real(acc[:, None] * np.exp(lam * t)[None, :])
    ell = rig.stock.bending_length_m
    cov = fd.amplitude_covariance(n, fs, np.array([f]), np.array([delta]), 0, np.full(len(gages), sigma))
    est = fd.full_damping(dict(zip(gages, acc, strict=True)), f, delta, rig, m.M[0, 0], m.M[1, 1], ell,
                          dict(zip(gages, cov, strict=True)))
    rng = np.random.default_rng(1836)
    got_in, got_C, got_c, ref_C, ref_c, phases = [], [], [], [], [], []
    names = [fl.name for fl in fields(fd.ModeMotions)]
    for _ in range(draws):
        b = pinv @ (clean + sigma * rng.standard_normal(clean.shape)).T
        amp = dict(zip(gages, b[0] - 1j * b[1], strict=True))
        mm = fd.motions_from_gages(amp, rig, ell)
        got_in.append(inputs(mm))
        C, c = fd.eq14_15(mm, f, delta, m.M[0, 0], m.M[1, 1], rig.rudder.Ixz_kg_m2, est.stock)
        got_C.append(C)
        got_c.append(c)
        # the same with the phase reference (v's phase) exact: only the other motions' phases err
        exact_ref = replace(mm, v=abs(mm.v) * motions.v / abs(motions.v))
        C, c = fd.eq14_15(exact_ref, f, delta, m.M[0, 0], m.M[1, 1], rig.rudder.Ixz_kg_m2, est.stock)
        ref_C.append(C)
        ref_c.append(c)
        phases.append([np.angle(getattr(mm, n) / getattr(motions, n)) for n in names])
    truth = inputs(motions)
    print(f"\n2. exact mode + white noise {sigma} m/s^2 rms, {seconds:g} s at {fs:g} Hz after the rig's blow "
          f"(|a| at gage 6: {abs(acc[gages.index(6)]):.3g} m/s^2), {draws} draws:")
    print(f"   {'input':10s} {'exact/v1':>11s} {'bias/v1':>10s} {'scatter/v1':>11s} {'scatter/exact':>13s}"
          f" {'as phase rad':>12s}")
    sin_exact = {k: v / abs(motions.v) for k, v in motions.quadrature()[0].items()}
    for name in INPUTS:
        x = np.array([g[name] for g in got_in])
        sd = np.std(x, ddof=1)
        # a cosine part's scatter is its motion's phase scatter times the sine part
        phase = f"{sd / abs(sin_exact[name[:-1]]):12.2e}" if name.endswith("2") else f"{'':12s}"
        print(f"   {name:10s} {truth[name]:+11.4e} {np.mean(x) - truth[name]:+10.2e} {sd:11.2e}"
              f" {sd / abs(truth[name]):13.2f} {phase}")
    share = []
    for g in fd.GAGES:  # noise on one gage at a time: each gage's share of C's and c's variance
        row = gages.index(g)
        Cs, cs = [], []
        for _ in range(draws // 4):
            y = clean[row] + sigma * rng.standard_normal(n)
            b = pinv @ y
            amp = dict(zip(gages, acc, strict=True)) | {g: b[0] - 1j * b[1]}
            C, c = fd.eq14_15(fd.motions_from_gages(amp, rig, ell), f, delta, m.M[0, 0], m.M[1, 1],
                              rig.rudder.Ixz_kg_m2, est.stock)
            Cs.append(C)
            cs.append(c)
        share.append((g, np.std(Cs, ddof=1), np.std(cs, ddof=1)))
    print("   scatter of C / c from one gage's noise alone: "
          + ", ".join(f"g{g} {sC:.2g} / {sc:.2g}" for g, sC, sc in share))
    print("   phase scatter of each motion (rad, absolute: the pole and t = 0 are exact): "
          + ", ".join(f"{n} {v:.2e}" for n, v in zip(names, np.std(phases, axis=0, ddof=1), strict=True)))
    print(f"   with v's phase (the reference) exact: C scatter {np.std(ref_C, ddof=1):.3g}, "
          f"c scatter {np.std(ref_c, ddof=1):.3g}")
    d = rig.active_damping
    for name, x, se, true in (("C", got_C, est.C_se, d.C_N_s_per_m),
                              ("c", got_c, est.c_se, d.c_N_m_s_per_rad)):
        x = np.array(x)
        sd = np.std(x, ddof=1)
        print(f"   {name}: mean {np.mean(x):.4g} +- {sd / np.sqrt(x.size):.2g} (rig {true:.4g}), "
              f"scatter {sd:.3g}, propagated s.e. {se:.3g} (ratio {sd / se:.3f}), "
              f"negative in {np.mean(x < 0) * 100:.0f} %, not significant in "
              f"{np.mean(np.abs(x) < fd.SIGNIFICANT_SE * se) * 100:.0f} %")

def section_recording(path: str, rig: Rig, exact: tuple) -> None:
    import ramdaq  # the analysis as ``ramdaq analyze`` runs it

    motions, *_ = exact
    truth = inputs(motions)
    res = ramdaq.analyze(path)
    d = res.rig.with_medium(rig.medium).active_damping
    print(f"\n3. {path}: each hit's inputs minus the exact mode's (units of v1), then Eq 14/15 +- s.e.")
    print("   hit " + " ".join(f"{n:>10s}" for n in INPUTS))
    for hit in res.hits:
        a = hit.analysis
        if a is None or a.damping.full is None:
            print(f"   {hit.index}: no Eq 14/15 ({hit.reason})")
            continue
        k = a.predominant
        amp = {n: a.modes.complex_amplitude[j, k] for j, n in enumerate(a.active_gages)}
        got = inputs(fd.motions_from_gages(amp, res.rig, a.damping.full.ell_m))
        print(f"   {hit.index:3d} " + " ".join(f"{got[n] - truth[n]:+10.2e}" for n in INPUTS))
        fu = a.damping.full
        print(f"       C = {fu.C_eq14_N_s_per_m:.4g} +- {fu.C_eq14_se_N_s_per_m:.2g} "
              f"({(fu.C_eq14_N_s_per_m - d.C_N_s_per_m) / fu.C_eq14_se_N_s_per_m:+.2f} s.e. from the rig's "
              f"{d.C_N_s_per_m:.4g}), c = {fu.c_eq15_N_m_s_per_rad:.4g} +- {fu.c_eq15_se_N_m_s_per_rad:.2g} "
              f"({(fu.c_eq15_N_m_s_per_rad - d.c_N_m_s_per_rad) / fu.c_eq15_se_N_m_s_per_rad:+.2f} s.e. from "
              f"{d.c_N_m_s_per_rad:.4g}), ell = {fu.ell_m:.4f} m (rig {res.rig.stock.bending_length_m})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="albacore")
    ap.add_argument("--medium", default="water")
    ap.add_argument("--draws", type=int, default=400)
    ap.add_argument("--recording", default=None, help="e.g. recordings/albacore-water.mcap")
    args = ap.parse_args()
    rig = load_rig(args.rig).with_medium(args.medium)
    exact = section_exact(rig)
    section_noise(rig, exact, args.draws)
    if args.recording:
        section_recording(args.recording, rig, exact)


if __name__ == "__main__":
    main()
