"""What an unmodelled effect is to the gap diagnosis: a term that switches on in the simulator,
where it can sit in a trial, and how it shows.

An :class:`Effect` is a stateless object with

* :meth:`Effect.placements` -- the discrete ways the effect could sit in this trial (which gage,
  which mode, which frequency...), each a :class:`Placement` with its continuous parameters'
  start values, bounds and *probe* values. The probe is a modest size of the effect: the
  prediction with it, less the calibrated prediction, is the effect's **signature** -- the
  template the residual is matched against (a score test, see :mod:`ramdaq.analysis.gap.evidence`);
* hooks into the four stages of :class:`~ramdaq.analysis.gap.forward.Forward` -- ``rig``, ``model``,
  ``modes``, ``pulses`` / ``columns`` / ``units`` (signals) and ``output`` -- each the identity
  unless the effect overrides it.

A new effect is one new module in :mod:`ramdaq.analysis.gap.effects` defining a subclass with a
``name``; the registry finds it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ...model.rig import Rig
from ...model.structure import StructuralModel
from ..terms import Placement, Term, placement
from ..trialdata import summed_spectrum

__all__ = ["Effect", "Placement", "Term", "compared_modes", "gage_row", "placement", "residual_peaks",
           "rig_update", "rudder_gages", "summed_spectrum", "whiten_fitted"]

if TYPE_CHECKING:
    from ..calibrate import Calibration
    from ..forward import Fit, Forward, ModeSet


class Effect:
    """Base of every candidate effect; hooks default to "no change"."""

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""
    needs_force: ClassVar[bool] = False
    """True when the term depends on each impact's force (amplitude-dependent effects)."""

    def placements(self, fw: Forward, fit: Fit) -> list[Placement]:
        raise NotImplementedError

    def templates(self, fw: Forward, cal: Calibration, pl: Placement) -> np.ndarray | None:
        """Signature templates (k, N) when the effect can give them cheaper than by running
        the forward model at each probe (the default, ``None``)."""
        return None

    def direct_score(self, fw: Forward, cal: Calibration) -> tuple[float, Placement | None] | None:
        """A score (z) and placement read straight off the data, for effects whose signature
        is not a template (e.g. a converter at its rail); ``None`` to use templates."""
        return None

    def rig(self, rig: Rig, term: Term) -> Rig:
        return rig

    @classmethod
    def moves_modes(cls) -> bool:
        """True when the term changes the structure (its ``rig``, ``model`` or ``modes`` hook):
        the base constants that tune the modes must then be re-tuned with it."""
        return any(getattr(cls, h) is not getattr(Effect, h) for h in ("rig", "model", "modes"))

    @classmethod
    def changes_units(cls) -> bool:
        """True when the term changes the impacts' unit responses themselves (its ``units``
        hook): a prediction then makes them whole, not only the blocks a pulse writes."""
        return cls.units is not Effect.units

    @classmethod
    def retunes(cls) -> bool:
        """True when the constants that tune the modes must be re-tuned to the data's spectrum
        with the term on before its refit starts (an extra mode pulls the others): by default,
        when it changes the structure."""
        return cls.moves_modes()

    def placement_after(self, fw: Forward, cal: Calibration) -> Placement | None:
        """The placement read again from the data once a refit with the term on has moved the
        constants that hid it (``cal``: that refit); ``None`` (the default) when the placement
        does not depend on the constants."""
        return None

    def model(self, model: StructuralModel, term: Term) -> StructuralModel:
        return model

    def modes(self, ms: ModeSet, fw: Forward, term: Term) -> ModeSet:
        return ms

    def pulses(self, term: Term) -> list[tuple[float | np.ndarray, float]]:
        """Extra ram contacts of every impact: (delay s, peak ratio) pairs; a delay may be an
        array (n_seg,), one per impact."""
        return []

    def columns(self, fw: Forward, term: Term) -> np.ndarray | None:
        """Extra linear columns (k, n_seg, n_gages, n_s) whose coefficients are solved with the
        impacts' forces."""
        return None

    def units(self, U: np.ndarray, dU: np.ndarray, ms: ModeSet, fw: Forward,
              force: np.ndarray | None, term: Term) -> tuple[np.ndarray, np.ndarray]:
        """The unit responses and their derivatives (n_seg, n_seg, n_gages, n_s) with this
        term's change of them. ``U`` and ``dU`` are the caller's own, made for this call
        (:meth:`Forward.unit_responses`): they may be changed in place and returned."""
        return U, dU

    def units_on_blocks(self, blocks: dict[tuple[int, int], list[np.ndarray]], ms: ModeSet,
                        fw: Forward, force: np.ndarray | None, term: Term) -> bool:
        """This term's change of the unit responses made on the blocks a pulse writes
        (:meth:`Forward.unit_blocks`: ``{(impact, segment): [u, du]}``, segment >= impact), in
        place, a block added where it writes one no pulse did -- the numbers its :meth:`units`
        makes on those blocks of the dense form: True; False (no such form: the dense unit
        responses are then made)."""
        return False

    def output(self, pred: np.ndarray, fw: Forward, term: Term) -> tuple[np.ndarray, np.ndarray | None]:
        """Last word on the prediction; may return a mask (n_seg, n_g, n_s) of samples that
        still count."""
        return pred, None


def rig_update(terms: list[Term]) -> Callable[[Rig], Rig] | None:
    """The rig change of fitted ``terms`` (each one's :meth:`Effect.rig` hook, in turn) as one
    function of the rig, or None when no term changes the rig (a sensor, a pulse, a change of
    the model's matrices or modes only)."""
    own = [t for t in terms if type(t.effect).rig is not Effect.rig]
    if not own:
        return None

    def update(rig: Rig) -> Rig:
        for t in own:
            rig = t.effect.rig(rig, t)
        return rig
    return update


def gage_row(fw: Forward, number: int) -> int:
    """Row of report gage ``number`` in the trial's arrays."""
    return fw.td.gage_numbers.index(number)


def rudder_gages(rig: Rig) -> tuple[int, ...]:
    return tuple(g.number for g in rig.gages_by_channel() if g.body == "rudder")


def compared_modes(fw: Forward, fit: Fit) -> list[tuple[int, float]]:
    """(index, frequency Hz) of the fit's modes inside the compared band."""
    f = fit.modes.f_hz
    return [(i, float(f[i])) for i in range(len(f))
            if 0 < f[i] < fw.td.lowpass_hz and not fit.modes.exp_only[i]]


def whiten_fitted(fw: Forward, d: np.ndarray) -> np.ndarray:
    """A prediction difference (n_seg, n_g, n_s) as a template over the fitted segments."""
    fitted = np.flatnonzero(fw.td.fitted)
    return np.nan_to_num((d[fitted] * fw.mask[fitted] * fw.W[fitted]).ravel())


def residual_peaks(fw: Forward, fit: Fit, windows: tuple[str, ...], n: int,
                   rows: list[int] | None = None, avoid_hz: list[float] = (),
                   min_hz: float = 0.0) -> list[float]:
    """The ``n`` strongest narrow peaks (Hz) of the whitened residual's spectrum in ``windows``
    (summed over fitted segments and ``rows``), at least 4 % from every ``avoid_hz``."""
    td = fw.td
    rows = list(range(td.n_gages)) if rows is None else rows
    total = None
    n_fft = 4 * td.n_s
    for w in windows:
        sl = getattr(td.windows, w)
        r = np.nan_to_num(fit.resid[td.fitted][:, rows, sl] * fw.W[td.fitted][:, rows, sl])
        f, P = summed_spectrum(r, td.fs_hz, n_fft)
        total = P if total is None else total + P
    ok = (f > max(min_hz, 2 * td.fs_hz / td.n_s)) & (f < td.lowpass_hz)
    for a in avoid_hz:
        ok &= np.abs(f - a) > 0.04 * a
    peaks = [i for i in range(1, len(f) - 1)
             if ok[i] and total[i] >= total[i - 1] and total[i] > total[i + 1]]
    peaks.sort(key=lambda i: -total[i])
    out: list[float] = []
    for i in peaks:
        if all(abs(f[i] - o) > 0.04 * o for o in out):
            out.append(float(f[i]))
        if len(out) == n:
            break
    return out
