"""The GP mean reverts to zero where it does not stand out from its own uncertainty.

A GP fitted on one flight predicts another flight's residual from the trends
of the first. Where the new flight combines the inputs otherwise (between the
branches of a figure-8, the gentle sweep of a chirp after the violent
transitions of attitude steps) the posterior mean still carries those trends,
with a latent variance that has grown but not to its prior: on the fit
flight's own samples the latent std is 1-3 % of the signal std, on such a
flight 10-25 %, and there the mean can be twice as wrong as predicting nothing
(docs/generalisation.md). Held-out time blocks of the fit flight cannot show
it: they fall where the flight already went.

So every prediction weighs the GP mean ``m`` by how far it stands beyond its
own band: with ``v`` the calibrated latent variance (posterior variance times
``latent_scale``, plus the growth beyond the training box)::

    w = m^2 / (m^2 + kappa v),    mean = w m,    variance += ((1 - w) m)^2

``kappa`` = :data:`MEAN_SHRINK` = 4 is the 2-sigma band: a mean as large as its
own 2-sigma half-width keeps half its value; one ten times its latent std keeps
96 %; on the fit flight's inputs (latent std a few % of the mean) it is
unchanged. Far from the data the mean goes to zero (physics only) while the band
grows. The added variance keeps the band around the unshrunk mean too, so the
band does not narrow where the GP was right after all. ``kappa`` was chosen on
``benchmarks/never_hurts.py`` and ``benchmarks/generalise.py`` (1 and 2 left a
held-out axis 1.32x and 1.10x worse than physics only; 4 none).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MEAN_SHRINK", "shrink_mean", "shrink_weight"]

#: Weight ``kappa`` on the latent variance against the squared GP mean (4: the
#: 2-sigma band). ``fit`` writes it per axis into the model (``mean_shrink``).
MEAN_SHRINK = 4.0


def shrink_mean(
    mean: np.ndarray, latent: np.ndarray, kappa: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The weighed GP mean (B, 3) and the variance (B, 3) it adds to the band.

    mean (B, 3) GP posterior mean (prior mean included), latent (B, 3) its
    calibrated latent variance, kappa (3,) per axis (0: the mean as it is).
    """
    w = shrink_weight(mean, latent, kappa)
    return w * mean, ((1.0 - w) * mean) ** 2


def shrink_weight(mean: np.ndarray, latent: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """The weight w (B, 3) in [0, 1] on the GP mean (B, 3) (1: kept as it is), for
    its calibrated latent variance (B, 3) and kappa (3,) (:func:`shrink_mean`)."""
    kappa = np.asarray(kappa, dtype=float)
    m2 = mean**2
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(kappa * latent > 0, m2 / (m2 + kappa * latent), 1.0)
    return np.asarray(np.nan_to_num(w, nan=1.0))
