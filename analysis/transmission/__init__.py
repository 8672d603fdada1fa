"""Transmission error (TE): the rig's second test (issue 22; docs/transmission-error.md).

Pure numerics: :mod:`.curve` (TE per direction on the output-angle grid), :mod:`.figures`
(GB/T 35089 peak-to-peak, ISO 1328-1 F'_i and f'_i, hysteresis), :mod:`.orders` (the spectrum
by order, least squares), :mod:`.eccentricity` (the encoder's mounting eccentricity by
reversal), :mod:`.analyse` (all of it with uncertainties), :mod:`.model` (the seeds'
prediction beside it) and :mod:`.compare` (where measurement and model part, by order).
"""

from analysis.transmission.analyse import METRIC_KEYS, Kinematics, TEResult, analyse_te

__all__ = ["METRIC_KEYS", "Kinematics", "TEResult", "analyse_te"]
