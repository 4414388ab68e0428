"""Whether a localisation succeeded: a verdict and a confidence for every result.

A rendered-view filter always returns its best pose, right or not. The verdict compares the
converged pose with what the model can do at all. The model is judged on its own map photos
first (`render_localizer.RenderModel.reference`): each map photo, textured without itself
(as a query would be), aligned at its known pose, gives the share of the photo's structure
the model explains there ("explained", `direct_alignment.Alignment`). A query is localised
when

- agreement: it explains about as much as the map photos do (explained / reference, ramped
  between `agreement`), so a pose in a wrong place, or a photo of a place the model does
  not show, falls short;
- support: enough of the photo is covered by trusted model (a ramp on the trusted share),
  so a few lucky pixels do not count;
- no rival: no distinct pose (more than `distinct_px` apart at the finest width) that would
  pass the agreement test itself reaches a cost within `rival_margin` of the best: an
  ambiguous photo (repeated facades, a plain wall) is "not localised" rather than a coin
  toss. A distinct pose that explains far less than the model does at its own photos is no
  rival, whatever its cost: the cost sums evidence over the trusted pixels, so a wrong pose
  that sees more trusted model can tie with the right one that sees a little of it well.

confidence = agreement x support x rival in [0, 1]; localized = confidence >= 0.5. All the
thresholds are ratios or shares (of the model's own performance, of the image), so they do
not depend on the scene's size or texture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from localization.direct_alignment import Alignment


@dataclass(frozen=True)
class ConfidenceConfig:
    """Settings of `judge`."""

    agreement: tuple[float, float] = (0.75, 0.95)
    """explained / reference: no confidence at the first ratio, full at the second."""
    support: tuple[float, float] = (0.015, 0.04)
    """Trusted share of the photo's pixels (at the finest width, 384 px): no confidence at the
    first, full at the second (about 1,700 and 4,400 trusted pixels). On a few per cent of
    trusted pixels the model's own optimum can be off: the two confident wrong answers seen
    on the courtyard (24 cm and 10 cm off, alignments from the truth ending there too) had
    2.5-2.6 %, while of 314 right flags over courtyard seeds 1-10, offices 1-5 and both
    Strecha sets one had under 3 % (the ramp was 0.5-2 % until then)."""
    rival_margin: float = 0.01
    """A distinct pose whose cost is within this (robust-cost units) of the best is a rival."""
    distinct_px: float = 8.0
    """Poses further apart than this (pixels at the finest width) are distinct."""


@dataclass
class Verdict:
    """localized; confidence in [0, 1]; reason: why not localised ("" when localised);
    explained, reference, trusted: see `judge`; rival_gap: cost of the best distinct rival
    minus the best's (None without a rival)."""

    localized: bool
    confidence: float
    reason: str
    explained: float | None = None
    reference: float | None = None
    trusted: float | None = None
    rival_gap: float | None = None

    def as_dict(self) -> dict:
        return {"localized": self.localized, "confidence": self.confidence, "reason": self.reason,
                "explained": self.explained, "reference": self.reference, "trusted": self.trusted,
                "rival_gap": self.rival_gap}


def ramp(x: float, lo: float, hi: float) -> float:
    """0 below lo, 1 above hi, linear between."""
    return float(np.clip((x - lo) / (hi - lo), 0.0, 1.0))


def plausible(candidate: Alignment, reference: float, config: ConfidenceConfig = ConfidenceConfig()) -> bool:
    """Whether a pose would pass the agreement test on its own (a possible rival)."""
    return ramp(candidate.explained / max(reference, 1e-6), *config.agreement) >= 0.5


def judge(best: Alignment, reference: float, rival_gap: float | None,
          config: ConfidenceConfig = ConfidenceConfig()) -> Verdict:
    """The verdict on an aligned pose `best` given the model's `reference` explained share at
    its own photos and the cost gap to the best distinct `plausible` rival pose."""
    ratio = best.explained / max(reference, 1e-6)
    agreement = ramp(ratio, *config.agreement)
    support = ramp(best.trusted, *config.support)
    rival = 1.0 if rival_gap is None else ramp(rival_gap, 0.0, config.rival_margin)
    confidence = agreement * support * rival
    reason = ""
    if confidence < 0.5:  # the first failed test, in order of how much it says
        if agreement < 0.5:
            reason = (f"the model explains {best.explained:.2f} of the photo's structure, "
                      f"{ratio:.0%} of what it explains at its own photos ({reference:.2f})")
        elif support < 0.5:
            reason = f"the trusted model covers only {best.trusted:.1%} of the photo"
        elif rival < 0.5:
            reason = f"a distinct pose explains the photo almost as well (cost gap {rival_gap:.4f})"
        else:
            reason = f"agreement {agreement:.2f} x support {support:.2f} x no rival {rival:.2f} is below 0.5"
    return Verdict(confidence >= 0.5, confidence, reason, best.explained, reference, best.trusted, rival_gap)


def pnp_verdict(n_inliers: int, n_matches: int, strong: tuple[int, float]) -> Verdict:
    """The verdict on a PnP pose: confident when it has at least `strong` = (inliers, inlier
    share of the matches); ramped from half of each."""
    need, share = strong
    if n_matches == 0:
        return Verdict(False, 0.0, "PnP found no pose")
    confidence = ramp(n_inliers, need / 2, need) * ramp(n_inliers / n_matches, share / 2, share)
    reason = "" if confidence >= 0.5 else (f"PnP pose weakly supported: {n_inliers} inliers of "
                                          f"{n_matches} matches")
    return Verdict(confidence >= 0.5, confidence, reason)
