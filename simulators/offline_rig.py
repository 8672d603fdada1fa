"""A real rig's measuring system around the offline plant (issue 20, point 4).

The plant (simulators/plant, stepped by :func:`simulators.offline.simulate_run`) gives the
unit's quasi-static answer: the chain torque ``G(t)`` the mesh carries and the twist it
holds. A real rig measures that through its own dynamics and instruments; each function here
adds one of those artefacts, none of them an effect of the unit:

- :func:`contact_transient`: the output inertia crossing the free play under the drive's
  small torque and hitting the flank, with a bounce or two (a spring-dashpot contact
  oscillator, locked resonance 350-1500 Hz, contact damping ratio 0.03-0.15), the drive's
  torque ripple as a real torque on the output, and a small Coulomb friction;
- :func:`first_order_lag`: the torque sensor's first-order lag (1-8 ms);
- :func:`zero_drift`: the torque zero re-tared before each run with a small residual, then
  random-walking during the run;
- :func:`adc`: the torque on an 18-24 bit ADC grid over the sensor's full scale;
- :func:`sample_clock`: sampling with timestamp jitter and dropped rows in bursts.

Units: torque N*m, twist rad (inside) / deg (columns), time s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.signal import lfilter

from simulators.plant.config import PlantConfig


@dataclass(frozen=True)
class RigArtifacts:
    """The sizes of one campaign's measuring-system artefacts (drawn per case)."""

    contact_damping_ratio: float
    locked_resonance_Hz: float
    torque_lag_s: float
    adc_bits: int
    torque_full_scale_Nm: float
    drive_loop_s: float
    tare_residual_Nm_rms: float
    zero_walk_Nm_rms: float  # rms drift of the zero over one run
    ripple_Nm: float
    ripple_Hz: float
    coulomb_Nm: float
    encoder_counts_per_rev: int
    sample_rate_Hz: float
    jitter_s: float
    dropped_bursts_mean: float  # per run
    max_burst: int
    precycles: int
    first_sign: int  # +1: the first loading is positive; -1: negative (from the -1 flank)

    @property
    def adc_step_Nm(self) -> float:
        """One ADC count (N*m): the bipolar full scale +-FS over 2^bits counts."""
        return 2.0 * self.torque_full_scale_Nm / 2.0 ** self.adc_bits

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "adc_step_Nm": self.adc_step_Nm}


def draw_artifacts(rng: np.random.Generator, rated_Nm: float,
                   full_scale_Nm: float) -> RigArtifacts:
    """Draw the artefact sizes of issue 20 point 4 (ranges in the field comments)."""
    return RigArtifacts(
        contact_damping_ratio=float(rng.uniform(0.03, 0.15)),
        locked_resonance_Hz=float(rng.uniform(350.0, 1500.0)),
        torque_lag_s=float(rng.uniform(0.001, 0.008)),
        adc_bits=int(rng.integers(18, 25)),
        torque_full_scale_Nm=float(full_scale_Nm),
        drive_loop_s=float(rng.uniform(0.005, 0.030)),
        tare_residual_Nm_rms=float(rng.uniform(0.0001, 0.0005) * rated_Nm),
        zero_walk_Nm_rms=float(rng.uniform(0.0002, 0.001) * rated_Nm),
        ripple_Nm=float(rng.uniform(0.0005, 0.002) * rated_Nm),
        ripple_Hz=float(rng.uniform(25.0, 300.0)),
        coulomb_Nm=float(rng.uniform(0.0002, 0.003) * rated_Nm),
        encoder_counts_per_rev=int(2 ** int(rng.integers(19, 24))),
        sample_rate_Hz=float(round(math.exp(rng.uniform(math.log(100.0), math.log(1000.0))))),
        jitter_s=float(rng.uniform(0.0, 0.0004)),
        dropped_bursts_mean=float(rng.uniform(0.5, 3.0)),
        max_burst=int(rng.integers(1, 41)),
        precycles=int(rng.integers(0, 3)),
        first_sign=int(rng.choice([-1, 1])),
    )


@dataclass(frozen=True)
class ContactOscillator:
    """The output on the mesh contact: ``J y'' = G(t) + R(t) - F_c(y, y') - F_f``.

    ``y`` the twist about the play centre (rad), ``G`` the plant's quasi-static chain torque,
    ``R = a sin(2 pi f_r t + phi)`` the drive's torque ripple, ``F_c`` the contact force of a
    linear spring-dashpot beyond the play ``+-h`` (stiffness ``k``, damping ``c = 2 zeta
    sqrt(k J)``, never pulling: a Kelvin-Voigt contact, Johnson, Contact Mechanics ch. 11),
    ``F_f`` a Coulomb friction (stick when the other torques are smaller). The locked
    resonance ``f_n = sqrt(k / J) / 2 pi`` fixes ``J``."""

    stiffness_Nm_per_rad: float
    resonance_Hz: float
    damping_ratio: float
    coulomb_Nm: float
    ripple_Nm: float
    ripple_Hz: float
    ripple_phase_rad: float

    @property
    def omega(self) -> float:
        return 2.0 * math.pi * self.resonance_Hz

    @property
    def inertia_kgm2(self) -> float:
        return self.stiffness_Nm_per_rad / self.omega ** 2

    @property
    def damping_Nms(self) -> float:
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness_Nm_per_rad * self.inertia_kgm2)

    def step_s(self) -> float:
        """The integration step (s): 0.1 rad of the locked resonance and of the ripple."""
        return 0.1 / max(self.omega, 2.0 * math.pi * self.ripple_Hz)

    def ripple_steady(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ripple's steady response in contact: twist (rad), velocity (rad/s) and the
        torque it puts through the contact (N*m), ``Y = R / (k - J w^2 + i c w)``."""
        w = 2.0 * math.pi * self.ripple_Hz
        k, c = self.stiffness_Nm_per_rad, self.damping_Nms
        amp = self.ripple_Nm * np.exp(1j * self.ripple_phase_rad) / (
            k - self.inertia_kgm2 * w * w + 1j * c * w)
        phase = w * np.asarray(t, dtype=float) + float(np.angle(amp))
        sin, cos = np.sin(phase), np.cos(phase)
        force = (k + 1j * c * w) * amp
        # sin convention: R = Im(a e^{i(wt + phi)}), so every response is the imaginary part
        turn = float(np.angle(k + 1j * c * w))  # the contact's phase lead
        return (abs(amp) * sin, abs(amp) * w * cos,
                abs(force) * (sin * math.cos(turn) + cos * math.sin(turn)))


def contact_transient(t: np.ndarray, chain_Nm: np.ndarray, half_play_rad: float,
                      osc: ContactOscillator, start_side: int = -1,
                      window_Nm: float | None = None) -> tuple[np.ndarray, np.ndarray,
                                                               dict[str, Any]]:
    """The dynamic departure of the output from the plant's quasi-static answer.

    ``t``: a uniform fine time grid (s) with ``chain_Nm`` the plant's chain torque on it
    (the reference: the plant crosses the play the instant ``G`` changes sign). Returns
    (twist departure ``y - y_qs`` (rad), torque departure ``F - G`` (N*m) of what the
    contact and friction pass to the unit, stats). ``y_qs = s h + G / k``, ``s`` the sign of
    the last non-zero ``G``. Where ``|G| > window_Nm`` (default: 4 times ripple plus friction
    plus 0.1 % of the largest ``G``) the output is on a flank in steady state: the departure
    is the ripple's steady response minus the friction's ``F_f / k`` against the motion.
    Where ``|G|`` is smaller the oscillator is integrated (semi-implicit Euler on
    :meth:`ContactOscillator.step_s`, friction implicit) until it has been in contact for 8
    decay times ``1 / (zeta w_n)`` on a loaded flank. Stats: ``impacts`` (contacts made),
    ``bounces`` (contacts lost again within a window while G pushes into the flank),
    ``windows``."""
    t = np.asarray(t, dtype=float)
    g = np.asarray(chain_Nm, dtype=float)
    n = t.size
    dt = float(t[1] - t[0]) if n > 1 else 1.0
    k, J, c = osc.stiffness_Nm_per_rad, osc.inertia_kgm2, osc.damping_Nms
    h, fc = float(half_play_rad), osc.coulomb_Nm
    if window_Nm is None:
        window_Nm = 4.0 * (osc.ripple_Nm + fc) + 1e-3 * float(np.max(np.abs(g), initial=0.0))
    yr, vr, fr = osc.ripple_steady(t)
    # direction of the loading (sign of the last non-zero change of G): friction opposes it
    dg = np.diff(g, prepend=g[0])
    direction = np.sign(dg)
    idx = np.where(direction != 0, np.arange(n), 0)
    np.maximum.accumulate(idx, out=idx)
    direction = direction[idx]
    direction[direction == 0] = -start_side
    # side of the quasi-static reference: the sign of the last non-zero G
    side = np.sign(g)
    idx = np.where(side != 0, np.arange(n), 0)
    np.maximum.accumulate(idx, out=idx)
    side = side[idx]
    side[side == 0] = start_side
    dy = yr - direction * fc / k
    df = fr.copy()
    small = np.abs(g) < window_Nm
    settle = 8.0 / (osc.damping_ratio * osc.omega)
    settle_n = max(1, int(math.ceil(settle / dt)))
    wr = 2.0 * math.pi * osc.ripple_Hz
    ra, rph = osc.ripple_Nm, osc.ripple_phase_rad
    impacts = bounces = windows = 0
    slip = dt * fc / J
    sin = math.sin
    chunk = max(settle_n * 4, 4096)
    i = 0
    while i < n:
        if not small[i]:
            nxt = np.flatnonzero(small[i:])
            if nxt.size == 0:
                break
            i += int(nxt[0])
        windows += 1
        # start at rest on the flank of the reference, the contact carrying G and the
        # ripple (the friction unloaded)
        y = float(side[i] * h + g[i] / k + yr[i])
        v = float(vr[i])
        in_contact = abs(y) > h
        contact_since = i
        done = False
        while not done and i < n:
            # the integration runs on Python floats (numpy scalars are several times slower),
            # a chunk of the grid at a time
            j = min(n, i + chunk)
            gl, tl, sl, sml = g[i:j].tolist(), t[i:j].tolist(), side[i:j].tolist(), \
                small[i:j + 1].tolist()
            ys, fs = [], []
            for m in range(j - i):
                gi = gl[m]
                drive = gi + ra * sin(wr * tl[m] + rph)
                if y > h:
                    fcontact = k * (y - h) + c * v
                    fcontact = fcontact if fcontact > 0.0 else 0.0
                elif y < -h:
                    fcontact = k * (y + h) + c * v
                    fcontact = fcontact if fcontact < 0.0 else 0.0
                else:
                    fcontact = 0.0
                v_free = v + dt * (drive - fcontact) / J
                if v_free > slip:
                    v, ffric = v_free - slip, fc
                elif v_free < -slip:
                    v, ffric = v_free + slip, -fc
                else:
                    v, ffric = 0.0, J * v_free / dt
                ys.append(y - (sl[m] * h + gi / k))
                fs.append(fcontact + ffric - gi)
                y += dt * v
                now = y > h or y < -h
                if now != in_contact:
                    if now:
                        impacts += 1
                    elif gi * y > 0.0:
                        bounces += 1
                    in_contact = now
                    contact_since = i + m
                if (m + 1 < len(sml) and not sml[m + 1] and in_contact and y * gi > 0.0
                        and i + m + 1 - contact_since >= settle_n):
                    done = True
                    break
            dy[i:i + len(ys)] = ys
            df[i:i + len(fs)] = fs
            i += len(ys)
    return dy, df, {"impacts": impacts, "bounces": bounces, "windows": windows}


def first_order_lag(t: np.ndarray, x: np.ndarray, tau_s: float) -> np.ndarray:
    """A first-order sensor ``tau y' + y = x`` on a uniform grid (exact for ``x`` held over
    each step), starting settled at ``x[0]``."""
    x = np.asarray(x, dtype=float)
    if tau_s <= 0.0 or x.size < 2:
        return x.copy()
    a = math.exp(-float(t[1] - t[0]) / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return y


def zero_drift(t: np.ndarray, residual_Nm: float, walk_Nm_rms: float,
               rng: np.random.Generator) -> np.ndarray:
    """The torque zero over a run (N*m): the tare's residual at t = 0 plus a Brownian walk
    whose rms after the run's duration is ``walk_Nm_rms`` (variance linear in time)."""
    t = np.asarray(t, dtype=float)
    span = max(float(t[-1] - t[0]), 1e-9)
    steps = rng.standard_normal(t.size) * np.sqrt(np.diff(t, prepend=t[0]) / span) * walk_Nm_rms
    return residual_Nm + np.cumsum(steps)


def adc(values: np.ndarray, bits: int, full_scale: float) -> np.ndarray:
    """A bipolar ADC of ``bits`` over +-``full_scale``: the nearest of ``2^bits`` counts,
    clipped at the ends."""
    step = 2.0 * full_scale / 2.0 ** bits
    counts = np.clip(np.round(np.asarray(values) / step), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return counts * step


def sample_clock(n: int, rate_Hz: float, jitter_s: float, bursts_mean: float, max_burst: int,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Timestamps and kept rows of ``n`` samples taken every ``1 / rate_Hz``: each stamp off
    its instant by a uniform error within +-``jitter_s``, and a Poisson number (mean
    ``bursts_mean``) of bursts of 1..``max_burst`` consecutive rows dropped (never the first
    or last row). Returns (stamps of all n, keep mask, burst lengths)."""
    t = np.arange(n) / rate_Hz + rng.uniform(-jitter_s, jitter_s, n)
    keep = np.ones(n, dtype=bool)
    lengths = []
    for _ in range(int(rng.poisson(bursts_mean))):
        length = int(rng.integers(1, max_burst + 1))
        if n < length + 10:
            continue
        start = int(rng.integers(1, n - length - 1))
        if not keep[start - 1:start + length + 1].all():
            continue  # bursts stay apart: each is one gap
        keep[start:start + length] = False
        lengths.append(length)
    return t, keep, lengths


#: The plant's output inertia while the artefacts are on (kg m^2): next to nothing, so the
#: plant answers quasi-statically and the output's dynamics come from the contact oscillator
#: alone (not twice).
QUASI_STATIC_INERTIA_KGM2 = 1e-6
#: The plant's own encoder while the artefacts are on: finer than any real one (the rig's
#: encoder quantises after the dynamics and the noise).
FINE_COUNTS = 2 ** 40


def measure_run(config: PlantConfig, profile_Nm: np.ndarray, art: RigArtifacts, *,
                twist_noise_arcsec: float, torque_noise_Nm: float, rng: np.random.Generator,
                input_angle_deg: float, temperature_C: float,
                extra_twist_arcmin: Callable[[np.ndarray], np.ndarray] | None = None
                ) -> dict[str, Any]:
    """One run of ``config``'s unit measured through a real rig (the module's artefacts).

    ``profile_Nm``: the drive command, one value per sample at ``art.sample_rate_Hz``. The
    plant steps quasi-statically with the drive's integral loop (``art.drive_loop_s``) as
    its torque lag; :func:`contact_transient` adds the output's crossing, impacts, bounces,
    ripple and Coulomb friction (locked resonance on the unit's linear stiffness); the
    torque then goes through the sensor's lag, the drifting zero, its noise and the ADC; the
    twist through its noise and the encoder; then the sample clock's jitter and dropped
    rows. ``extra_twist_arcmin``: twist (arcmin) of the flange torque the unit adds beyond
    the plant (other functional forms of an effect), on the quasi-static twist. Returns
    ``columns`` (t_s, torque_Nm, output_angle_deg, input_angle_deg,
    temperature_C: what run.json's samples get) and ``truth`` (the same rows before the
    measuring system: ``t_true_s``, ``shaft_torque_Nm``, ``zero_Nm``, ``twist_dynamic_deg``,
    the kept mask, the dropped bursts and the contact statistics)."""
    from simulators.offline import quantise_deg, simulate_run
    from simulators.plant.model import PlantModel

    fs = art.sample_rate_Hz
    n = int(np.asarray(profile_Nm).size)
    plant_cfg = config.with_changes(
        rig={"inertia_kgm2": QUASI_STATIC_INERTIA_KGM2, "drive_time_constant_s": art.drive_loop_s,
             "encoder_counts_per_rev": FINE_COUNTS, "start_flank": -1},
        noise={"twist_arcsec_rms": 0.0, "torque_Nm_rms": 0.0})
    cols = simulate_run(plant_cfg, profile_Nm, duration_s=n / fs, sample_rate_Hz=fs,
                        input_angle_deg=input_angle_deg, temperature_C=temperature_C)
    model = PlantModel(plant_cfg.with_changes(
        rig={"initial_input_angle_deg": float(input_angle_deg)},
        housing={"initial_C": float(temperature_C), "ambient_C": float(temperature_C)}))
    half_play = 0.5 * model.play_rad()
    osc = ContactOscillator(1.0 / model.compliance.c_lin, art.locked_resonance_Hz,
                            art.contact_damping_ratio, art.coulomb_Nm, art.ripple_Nm,
                            art.ripple_Hz, float(rng.uniform(0.0, 2.0 * math.pi)))
    t = cols["t_s"]
    sub = max(1, math.ceil((1.0 / fs) / osc.step_s() - 1e-9))
    t_f = np.arange(n * sub) * (1.0 / fs / sub)
    chain_f = np.interp(t_f, t, cols["chain_torque_Nm"])
    dy, df, stats = contact_transient(t_f, chain_f, half_play, osc, start_side=-1)
    twist_dyn_deg = np.degrees(dy[::sub])
    shaft_f = np.interp(t_f, t, cols["torque_Nm"]) + df  # the reading effects are in it
    sensed = first_order_lag(t_f, shaft_f, art.torque_lag_s)[::sub]
    zero = zero_drift(t, float(rng.normal(0.0, art.tare_residual_Nm_rms)),
                      art.zero_walk_Nm_rms, rng)
    torque = adc(sensed + zero + rng.standard_normal(n) * torque_noise_Nm, art.adc_bits,
                 art.torque_full_scale_Nm)
    counts = art.encoder_counts_per_rev
    quasi_static = cols["output_angle_deg"]
    if extra_twist_arcmin is not None:
        quasi_static = quasi_static + extra_twist_arcmin(cols["true_torque_Nm"]) / 60.0
    out = (quasi_static + twist_dyn_deg
           + rng.standard_normal(n) * twist_noise_arcsec / 3600.0)
    stamps, keep, bursts = sample_clock(n, fs, art.jitter_s, art.dropped_bursts_mean,
                                        art.max_burst, rng)
    columns = {"t_s": stamps[keep], "torque_Nm": torque[keep],
               "output_angle_deg": quantise_deg(out, counts)[keep],
               "input_angle_deg": quantise_deg(cols["input_angle_deg"], counts)[keep],
               "temperature_C": cols["temperature_C"][keep]}
    truth = {"t_true_s": t, "shaft_torque_Nm": shaft_f[::sub], "zero_Nm": zero,
             "twist_dynamic_deg": twist_dyn_deg, "keep": keep, "bursts": bursts,
             "contact": stats, "half_play_rad": half_play, "ripple_phase_rad": osc.ripple_phase_rad,
             "inertia_kgm2": osc.inertia_kgm2}
    return {"columns": columns, "truth": truth}
