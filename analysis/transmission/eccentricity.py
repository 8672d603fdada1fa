"""The output encoder's mounting eccentricity: separated from the unit's own once-per-turn TE
by a reversal, and removed from later runs.

An encoder disk mounted off the output's axis by ``e`` reads an angle error ``E(theta_enc)``
of one cycle per turn of the disk (``e / R`` rad for a reading radius ``R``); in one run it is
indistinguishable from the unit's own once-per-output-revolution TE ``U(theta)``. The reversal
(the classic two-position method of roundness and encoder metrology): two TE runs, the second
with the coupling between the output and the encoder indexed by 180 deg. In the frame of the
encoder's reading (``output_angle_deg``) the encoder's term keeps its phase and the unit's
flips sign, so with the fitted order-1 phasors ``Z_A = E + U`` and ``Z_B = E - U``::

    E = (Z_A + Z_B) / 2        U = (Z_A - Z_B) / 2

each with standard uncertainty ``sqrt(u_A^2 + u_B^2) / 2``. ``E`` is stored with the output
encoder's calibration (rig configuration ``[calibration.encoder]`` ``eccentricity_arcsec``,
``eccentricity_phase_deg``, ``eccentricity_u_arcsec``) and subtracted from every later run:
``TE - E_A cos(theta_enc + E_p)``. Phasors follow :mod:`analysis.transmission.orders`
(``A cos(phi + p)``, ``A exp(i p)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class EncoderEccentricity:
    """The encoder's once-per-turn error ``amplitude_arcsec cos(theta_enc + phase_deg)`` and
    the standard uncertainty of its amplitude (arcsec, each phasor component)."""

    amplitude_arcsec: float
    phase_deg: float
    u_arcsec: float
    source: str = "reversal calibration"

    def arcsec(self, output_angle_deg: np.ndarray) -> np.ndarray:
        """The encoder's error (arcsec) at its reading ``output_angle_deg``."""
        return self.amplitude_arcsec * np.cos(np.radians(output_angle_deg)
                                              + math.radians(self.phase_deg))

    def to_dict(self) -> dict[str, Any]:
        return {"amplitude_arcsec": self.amplitude_arcsec, "phase_deg": self.phase_deg,
                "u_arcsec": self.u_arcsec, "source": self.source}


def reversal(phasor_a: complex, u_a: float, phasor_b: complex, u_b: float
             ) -> tuple[EncoderEccentricity, complex]:
    """Separate the encoder's and the unit's order-1 terms from run A (coupling at 0 deg) and
    run B (coupling indexed by 180 deg): ``(E, U)`` with ``E = (Z_A + Z_B) / 2`` and
    ``U = (Z_A - Z_B) / 2`` (arcsec phasors); ``u`` = ``sqrt(u_A^2 + u_B^2) / 2``."""
    e = 0.5 * (phasor_a + phasor_b)
    u = 0.5 * math.hypot(u_a, u_b)
    return (EncoderEccentricity(float(abs(e)), float(np.degrees(np.angle(e))), float(u)),
            0.5 * (phasor_a - phasor_b))
