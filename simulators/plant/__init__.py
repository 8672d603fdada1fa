"""GearPlant: the simulated gear unit on the rig, behind simulators.plant.api.Plant.

A deterministic time-domain model (simulators/plant/model.py) advanced to an injectable
clock on every call, thread-safe, with sensor noise. The protocol faces read
:meth:`GearPlant.snapshot`; tests read the true loop back with :meth:`true_parameters`,
:meth:`true_twist_arcmin` and :meth:`true_lost_motion_arcmin`. docs/plant.md has the physics.

Sign conventions: positive torque twists the output positively; the output turns opposite to
the eccentric shaft: ``output_angle_deg = offset - input_angle_deg / ratio + twist`` with
``ratio = z_external / (z_internal - z_external)`` (8 for 45/40; 39 for a 40/39 cycloid pair)
or, for a beveloid pair, ``z_gear / z_pinion``. The unit's ``kind`` chooses the geometry
(:func:`simulators.plant.kinds.geometry_for`, docs/unit-kinds.md).
"""

from __future__ import annotations

import bisect
import copy
import math
import threading
from collections import deque

import numpy as np

from simulators.clock import Clock, MonotonicClock
from simulators.plant.api import PlantSnapshot
from simulators.plant.config import PlantConfig
from simulators.plant.geometry import ARCMIN_PER_RAD
from simulators.plant.model import PlantModel

_FAST_FORWARD_MIN_STEPS = 16
HISTORY_S = 4.0
"""How far back (s) :meth:`GearPlant.snapshot_at_monotonic` can look: a simulated device
starved of the CPU this long still samples at the moment it was asked to."""


class GearPlant:
    """The unit on the rig (implements simulators.plant.api.Plant; thread-safe).

    ``clock`` defaults to a MonotonicClock (real time); pass a ManualClock for tests. The
    model advances in fixed steps of ``rig.step_s`` on a grid started at construction; a
    snapshot between grid points is interpolated linearly. While the plant is at rest
    (drive settled, output still) long waits are crossed in one long implicit step.
    """

    def __init__(self, config: PlantConfig, clock: Clock | None = None) -> None:
        self.config = config
        self.clock = clock if clock is not None else MonotonicClock()
        self._lock = threading.Lock()
        self._model = PlantModel(config)
        self._t0 = self.clock.now_s()
        self._n = 0
        self._rng = np.random.default_rng(config.noise.seed)
        self._twist_noise_deg = config.noise.twist_arcsec_rms / 3600.0
        self._torque_noise = config.noise.torque_Nm_rms
        meas = config.measurement
        self._zero_residual = meas.torque_zero_residual_Nm
        self._zero_walk = meas.torque_zero_walk_Nm_per_sqrt_s
        self._zero_Nm = 0.0
        self._zero_t = 0.0
        self._adc_lsb = (2.0 * meas.torque_adc_full_scale_Nm / 2.0 ** meas.torque_adc_bits
                         if meas.torque_adc_bits else 0.0)
        self._prev = self._current = self._state()
        # (time s, state) of the grid points stepped, newest last: the past a device that
        # samples on a trigger (an encoder on SYNC) reads when it was starved of the CPU
        self._history: deque[tuple[float, tuple[float, ...]]] = deque(
            [(0.0, self._current)], maxlen=max(16, int(HISTORY_S / self._model.dt)))

    # -- time ------------------------------------------------------------------------------
    def _state(self) -> tuple[float, ...]:
        m = self._model
        return (m.output_angle_deg(), m.input_deg, m.flange_Nm, m.temperature_C, m.sensor_Nm)

    def _advance(self) -> float:
        """Step the model to the first grid point at or after the clock; return the time."""
        now = self.clock.now_s() - self._t0
        dt = self._model.dt
        target = math.ceil(now / dt - 1e-9)
        while self._n < target:
            remaining = target - self._n
            if remaining > _FAST_FORWARD_MIN_STEPS and self._model.is_quiescent():
                jump = remaining - 1
                self._model.step(jump * dt)
                self._n += jump
            else:
                self._prev = self._state()
                self._model.step(dt)
                self._n += 1
            self._current = self._state()
            self._history.append((self._n * dt, self._current))
        return now

    def _interpolated(self, now: float) -> tuple[float, ...]:
        dt = self._model.dt
        frac = 1.0 - (self._n * dt - now) / dt
        if frac >= 1.0 or self._n == 0:
            return self._current
        frac = max(frac, 0.0)
        return tuple(p + frac * (c - p) for p, c in zip(self._prev, self._current, strict=True))

    # -- Plant protocol --------------------------------------------------------------------
    def snapshot(self) -> PlantSnapshot:
        """Advance to the clock's time and return the sensors' view (noise included)."""
        with self._lock:
            now = self._advance()
            return self._sensed(now, self._interpolated(now))

    def snapshot_at_monotonic(self, t_mono_s: float) -> PlantSnapshot:
        """The sensors' view at host ``time.monotonic()`` time ``t_mono_s`` (s), at most
        :data:`HISTORY_S` back (and never after now): what a device that samples on a
        trigger (an encoder on the SYNC it received at ``t_mono_s``) measured, however late
        its thread got the CPU. With a clock that is not the host's (a ManualClock): now."""
        at_monotonic = getattr(self.clock, "at_monotonic", None)
        if at_monotonic is None:
            return self.snapshot()
        t = at_monotonic(float(t_mono_s)) - self._t0  # the plant's time, as _advance's
        with self._lock:
            now = self._advance()
            if not t < now:
                return self._sensed(now, self._interpolated(now))
            history = self._history
            i = bisect.bisect_right(history, t, key=lambda h: h[0])
            if i == 0:  # older than the history: its oldest point
                t, state = history[0]
            elif i == len(history):
                state = history[-1][1]
            else:
                (t0, s0), (t1, s1) = history[i - 1], history[i]
                w = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                state = tuple(a + w * (b - a) for a, b in zip(s0, s1, strict=True))
            return self._sensed(t, state)

    def _sensed(self, now: float, state: tuple[float, ...]) -> PlantSnapshot:
        """The sensors' view (noise, zero error, ADC grid) of the model ``state`` at time
        ``now`` (s). Called holding the lock."""
        out_deg, in_deg, true_Nm, temp, sensed_Nm = state
        m = self._model
        torque = m.sensor_torque_Nm(sensed_Nm) + self._torque_zero(now)
        if self._twist_noise_deg or self._torque_noise:
            noise_twist, noise_torque = self._rng.standard_normal(2).tolist()
            out_deg += noise_twist * self._twist_noise_deg
            torque += noise_torque * self._torque_noise
        if self._adc_lsb:
            torque = round(torque / self._adc_lsb) * self._adc_lsb
        return PlantSnapshot(
            t_s=now,
            output_angle_deg=out_deg,
            input_angle_deg=in_deg,
            torque_Nm=torque,
            true_torque_Nm=true_Nm,
            temperature_C=temp,
            torque_command_Nm=m.command_Nm,
            drive_enabled=m.enabled,
        )

    def command_torque(self, torque_Nm: float) -> None:
        """Set the drive's torque setpoint (N*m); the drive clips it to its torque limit."""
        value = _finite(torque_Nm, "torque command must be a finite number of N*m")
        self._set_model(command_Nm=value)

    def _set_model(self, **values: float) -> None:
        """Advance the model to now, then set its attributes ``values`` (in order)."""
        with self._lock:
            self._advance()
            for name, value in values.items():
                setattr(self._model, name, value)

    def enable_drive(self, enabled: bool) -> None:
        """Enable the drive, or disable it (its torque decays to zero with the loop lag).
        Enabling a disabled drive starts a run: the torque channel is re-tared then, leaving
        a residual zero of ``measurement.torque_zero_residual_Nm`` rms."""
        with self._lock:
            now = self._advance()
            if enabled and not self._model.enabled and self._zero_residual:
                self._zero_Nm = float(self._rng.standard_normal()) * self._zero_residual
                self._zero_t = now
            self._model.enabled = bool(enabled)

    def _torque_zero(self, now: float) -> float:
        """The torque channel's zero error (N*m) at ``now``: the residual of the last re-tare
        plus a random walk of ``measurement.torque_zero_walk_Nm_per_sqrt_s``."""
        if self._zero_walk and now > self._zero_t:
            step = self._zero_walk * math.sqrt(now - self._zero_t)
            self._zero_Nm += float(self._rng.standard_normal()) * step
            self._zero_t = now
        return self._zero_Nm

    def lock_input_at(self, angle_deg: float) -> None:
        """Turn the eccentric shaft to ``angle_deg`` (at rig.input_speed_deg_per_s) and lock."""
        value = _finite(angle_deg, "input angle must be a finite number of deg")
        self._set_model(input_speed_deg_s=self.config.rig.input_speed_deg_per_s,
                        input_target_deg=value)

    def turn_input(self, speed_deg_per_s: float) -> float:
        """Turn the eccentric shaft (input) at a constant speed (deg/s; the sign is the
        direction, + forward) until :meth:`stop_input` or :meth:`lock_input_at`; 0 stops
        it. Returns the input angle (deg) at the command."""
        value = _finite(speed_deg_per_s, "input speed must be a finite number of deg/s")
        with self._lock:
            self._advance()
            m = self._model
            if value == 0.0:
                m.input_target_deg = m.input_deg
            else:
                m.input_speed_deg_s = abs(value)
                m.input_target_deg = math.copysign(math.inf, value)
            return m.input_deg

    def stop_input(self) -> float:
        """Stop the input where it is and hold it there; returns that angle (deg)."""
        return self.turn_input(0.0)

    def input_speed_deg_per_s(self) -> float:
        """The input's speed now (deg/s, signed; 0 when it stands or is locked)."""
        with self._lock:
            self._advance()
            m = self._model
            if m.input_deg == m.input_target_deg:
                return 0.0
            return math.copysign(m.input_speed_deg_s, m.input_target_deg - m.input_deg)

    def set_ambient_temperature(self, celsius: float) -> None:
        """Set the ambient/heater setpoint the housing temperature follows (deg C)."""
        self._set_model(ambient_C=_finite(celsius, "ambient temperature must be finite deg C"))

    # -- truth for tests -------------------------------------------------------------------
    def _scratch(self) -> PlantModel:
        model = copy.copy(self._model)
        model.friction = copy.copy(self._model.friction)
        return model

    def true_parameters(self) -> dict:
        """The true loop now (at the current lock angle and housing temperature).

        Keys (vocabulary units): ``play_arcmin`` (the whole dead zone at zero torque: mesh
        with runout, spacing, thermal terms, plus bearing clearance), its parts
        ``*_play_arcmin`` and ``mesh_play_um``; ``stiffness_Nm_per_arcmin`` (the flank slope
        at high torque: mesh in series with shaft compliance), ``mesh_stiffness_*``;
        ``apparent_play_arcmin`` (high-torque flanks extrapolated to zero torque);
        ``friction_torque_Nm``, ``torque_sensor_offset_Nm``, and each effect's parameters.
        """
        with self._lock:
            self._advance()
            m = self._model
            geo = m.geometry
            fx = self.config.effects
            theta, temp = m.input_deg, m.temperature_C
            mesh_um = m.mesh_play_um()
            play = m.play_rad() * ARCMIN_PER_RAD
            c = m.compliance
            stiffness = 1.0 / (c.c_lin * ARCMIN_PER_RAD)
            extra = c.soft_rad + c.bearing_c * c.bearing_torque_Nm
            n, tooth_int, tooth_ext = geo.tooth_pair(theta)
            params = {
                "play_arcmin": play,
                "play_um": mesh_um + geo.bearing_play_um,
                "mesh_play_um": mesh_um,
                "mesh_play_arcmin": geo.arcmin_from_um(mesh_um),
                "nominal_play_arcmin": geo.nominal.play_arcmin,
                "runout_play_arcmin": geo.arcmin_from_um(geo.runout_play_um(theta)),
                "runout_center_distance_change_um": 1000.0 * (
                    geo.center_distance_mm(theta) - geo.eccentric_distance_mm
                ) if geo.runout_on else 0.0,
                "spacing_play_arcmin": geo.arcmin_from_um(geo.spacing_play_um(theta)),
                "thermal_play_arcmin": geo.arcmin_from_um(geo.thermal_play_um(temp)),
                "bearing_play_arcmin": geo.arcmin_from_um(geo.bearing_play_um),
                "apparent_play_arcmin": play + 2.0 * extra * ARCMIN_PER_RAD,
                "twist_offset_arcmin": m.pitch_offset_rad() * ARCMIN_PER_RAD,
                "stiffness_Nm_per_arcmin": stiffness,
                "mesh_stiffness_Nm_per_arcmin": geo.nominal.stiffness_Nm_per_arcmin,
                "mesh_stiffness_N_per_um": geo.nominal.mesh_stiffness_N_per_um,
                "contact_ratio": geo.nominal.contact_ratio,
                "working_pressure_angle_deg": geo.nominal.working_pressure_angle_deg,
                "shaft_stiffness_Nm_per_arcmin": fx.shaft_compliance.stiffness_Nm_per_arcmin
                if fx.shaft_compliance.enabled else math.inf,
                "friction_torque_Nm": m.friction.quasi_static_level_Nm() if m.friction else 0.0,
                "torque_sensor_offset_Nm": fx.torque_sensor_offset.offset_Nm
                if fx.torque_sensor_offset.enabled else 0.0,
                "torque_gain_positive": fx.direction_gain.gain_positive
                if fx.direction_gain.enabled else 1.0,
                "torque_gain_negative": fx.direction_gain.gain_negative
                if fx.direction_gain.enabled else 1.0,
                "stiffening_twist_arcmin": c.soft_rad * ARCMIN_PER_RAD,
                "stiffening_torque_Nm": c.soft_scale_Nm if c.soft_rad else 0.0,
                "bearing_soft_stiffness_Nm_per_arcmin": 1.0 / (c.bearing_c * ARCMIN_PER_RAD)
                if c.bearing_c else math.inf,
                "bearing_soft_stage_torque_Nm": c.bearing_torque_Nm,
                "creep_stiffness_Nm_per_arcmin": 1.0 / (m.creep_c * ARCMIN_PER_RAD)
                if m.creep_c else math.inf,
                "creep_time_constant_s": self.config.effects.creep.time_constant_s
                if m.creep_c else 0.0,
                "creep_twist_arcmin": m.creep_rad * ARCMIN_PER_RAD,
                "temperature_C": temp,
                "input_angle_deg": theta,
                "tooth_index": n,
                "tooth_internal": tooth_int,
                "tooth_external": tooth_ext,
                "ratio": m.ratio,
                "drive_torque_Nm": m.drive_Nm,
                "effects": fx.enabled_names(),
                "kind": geo.kind,
            }
            params.update(geo.kind_truth(theta))
            return params

    def true_transmission_error(self, brake_torque_Nm: float, points_per_input_rev: int = 720,
                                orders: list[int] | None = None, *,
                                output_window_deg: tuple[float, float] | None = None,
                                points_per_output_rev: int | None = None) -> dict:
        """Quasi-static truth of a transmission error run (docs/run-format.md): the unit's TE
        (arcsec) over one output revolution from the input angle now, in each direction,
        under a brake torque of magnitude ``brake_torque_Nm`` (N*m) against the output's
        motion, at the current housing temperature, friction and dynamics off.

        The output sits on the flank ``s`` the brake pushes it to (forward input: the output
        turns negative, the brake pushes it positive, ``s = +1``), so its twist is
        ``c(theta) + s (play(theta) / 2 + h(T))``: the pitch deviations and the
        eccentricities' kinematic error in ``c`` (geometry.kinematic_error_um), the runout's
        play (seed 000 eqs. 3, 4, 7) and the elastic twist on the flank.
        ``TE = 3600 * twist_deg`` minus each direction's mean (run-format's ``c_d``); the
        output encoder's mounting eccentricity is a reading error, reported apart under
        ``encoder_eccentricity`` and not in the unit's TE.

        Returns ``forward``/``reverse``: ``output_angle_deg`` (nominal, the output encoder's
        angle without errors), ``input_angle_deg``, ``te_arcsec``, ``pp_arcsec``;
        ``te_pp_arcsec`` (the larger direction's), ``te_hysteresis_arcmin`` (forward mean
        minus reverse mean: play plus twice the elastic twist), ``te_orders`` (per output
        revolution, ``TE ~ A cos(k theta_out + phase)`` with ``theta_out`` the output angle,
        rad; default orders: the eccentricities' ``ratio`` and ``ratio + 1``),
        ``encoder_eccentricity`` and ``injected`` (every injected value).

        A ``planetary`` unit (seed 003) has its own truth,
        :func:`simulators.plant.planetary.planetary_true_transmission_error`: the output turns
        with the input, TE is seed 003 eq. (11) of the unit's drawn errors, over one output
        revolution from now or over the output angles ``output_window_deg`` (the revolution an
        analysis used), ``points_per_output_rev`` points."""
        torque = abs(float(brake_torque_Nm))
        if not math.isfinite(torque):
            raise ValueError(f"brake torque must be finite, got {brake_torque_Nm!r}")
        with self._lock:
            self._advance()
            model = self._scratch()
        geo = model.geometry
        if geo.kind == "planetary":
            from simulators.plant.planetary import planetary_true_transmission_error

            return planetary_true_transmission_error(
                geo, play_rad=model.play_rad(), elastic_rad=model.compliance(torque)[0],
                start_input_deg=model.input_deg,
                output_offset_deg=self.config.rig.output_offset_deg, brake_torque_Nm=torque,
                output_window_deg=output_window_deg,
                **({"points_per_output_rev": points_per_output_rev}
                   if points_per_output_rev else {}))
        if output_window_deg is not None or points_per_output_rev is not None:
            raise ValueError("output_window_deg and points_per_output_rev are for a planetary "
                             "unit's truth")
        ratio = model.ratio
        n = int(round(ratio * points_per_input_rev))
        start = model.input_deg
        offset = self.config.rig.output_offset_deg
        h_rad = model.compliance(torque)[0]
        out: dict = {}
        means = {}
        for name, s in (("forward", 1.0), ("reverse", -1.0)):
            theta = start + s * 360.0 * ratio * np.arange(n) / n
            twist = np.empty(n)
            for i, th in enumerate(theta):
                model.input_deg = float(th)
                twist[i] = model.pitch_offset_rad() + s * (0.5 * model.play_rad() + h_rad)
            te = twist * ARCMIN_PER_RAD * 60.0
            means[name] = float(te.mean())
            te = te - te.mean()
            out[name] = {"input_angle_deg": theta, "output_angle_deg": offset - theta / ratio,
                         "te_arcsec": te, "pp_arcsec": float(te.max() - te.min())}
        out["te_pp_arcsec"] = max(out["forward"]["pp_arcsec"], out["reverse"]["pp_arcsec"])
        out["te_pp_forward_arcsec"] = out["forward"]["pp_arcsec"]
        out["te_pp_reverse_arcsec"] = out["reverse"]["pp_arcsec"]
        out["te_hysteresis_arcmin"] = (means["forward"] - means["reverse"]) / 60.0
        wanted = orders if orders is not None else (
            [int(round(ratio)), int(round(ratio)) + 1] if geo.kinematic_on else [])
        out["te_orders"] = [
            {**te_order(out[name]["output_angle_deg"], out[name]["te_arcsec"], k),
             "direction": name}
            for name in ("forward", "reverse") for k in wanted]
        rig = self.config.rig
        out["encoder_eccentricity"] = {
            "order": 1, "per": "output_rev", "amplitude_arcsec": rig.encoder_eccentricity_arcsec,
            "phase_deg": _wrap_deg(rig.encoder_eccentricity_phase_deg - 90.0),
            "form": "reading error E sin(theta_out + encoder_eccentricity_phase_deg)"}
        fx = self.config.effects
        out["injected"] = {
            "ratio": -ratio, "brake_torque_Nm": torque,
            "kinematic_error": {"enabled": geo.kinematic_on,
                                "internal_um": geo.kinematic_internal_um,
                                "external_um": geo.kinematic_external_um,
                                "internal_phase_deg": fx.kinematic_error.internal_phase_deg,
                                "beta_deg": fx.kinematic_error.beta_deg,
                                "internal_order": ratio, "external_order": ratio + 1.0},
            "pitch_internal_um": geo.pitch_internal_um.tolist() if geo.spacing_on else [],
            "pitch_external_um": geo.pitch_external_um.tolist() if geo.spacing_on else [],
            "runout": fx.runout.enabled,
            "encoder_eccentricity_arcsec": rig.encoder_eccentricity_arcsec,
            "encoder_eccentricity_phase_deg": rig.encoder_eccentricity_phase_deg,
            "drive_ripple_Nm": rig.drive_ripple_Nm, "drive_ripple_Hz": rig.drive_ripple_Hz,
        }
        return out

    def true_twist_arcmin(self, torque_Nm: np.ndarray, start_flank: int = -1) -> np.ndarray:
        """Quasi-static truth: the twist (arcmin, output angle minus ``-input / ratio``, zero
        at the centre of the nominal play) along a slow path of flange torques ``torque_Nm``
        (the torque through the unit, before the sensor's offset/gain), starting at rest on
        ``start_flank`` after a preload (rig.preload_torque_Nm), at the current lock angle and
        housing temperature. Friction and creep are in their slow limits."""
        if start_flank not in (-1, 1):
            raise ValueError(f"start_flank must be -1 or +1, got {start_flank!r}")
        torques = np.asarray(torque_Nm, dtype=float).ravel()
        if not np.all(np.isfinite(torques)):
            raise ValueError("torque_Nm must be finite")
        with self._lock:
            self._advance()
            model = self._scratch()
        return np.asarray(model.quasi_static_path(torques, start_flank)) * ARCMIN_PER_RAD

    def true_lost_motion_arcmin(self, rated_torque_Nm: float, pct: float) -> float:
        """Lost motion (arcmin) of the quasi-static loop: the difference of the loop's mid
        twists (mean of the two branches) at +pct % and -pct % of the rated torque, on a cycle
        0 -> +T -> -T -> +T (Nabtesco/GB/T definition; includes the elastic twist)."""
        if not (rated_torque_Nm > 0 and 0 < pct <= 100):
            raise ValueError(f"need rated torque > 0 and 0 < pct <= 100, got "
                             f"{rated_torque_Nm!r}, {pct!r}")
        n = 2001
        up = np.linspace(0.0, rated_torque_Nm, n)
        down = np.linspace(rated_torque_Nm, -rated_torque_Nm, 2 * n)
        back = np.linspace(-rated_torque_Nm, rated_torque_Nm, 2 * n)
        twist = self.true_twist_arcmin(np.concatenate([up, down, back]))
        unloading = twist[n:3 * n]
        loading = twist[3 * n:]
        level = rated_torque_Nm * pct / 100.0

        def mid(torque: float) -> float:
            a = np.interp(torque, down[::-1], unloading[::-1])
            b = np.interp(torque, back, loading)
            return 0.5 * (a + b)

        return float(mid(level) - mid(-level))


def te_order(output_angle_deg: np.ndarray, te_arcsec: np.ndarray, order: int) -> dict:
    """The order-``order`` term of a TE curve sampled uniformly over one output revolution:
    ``TE ~ A cos(order theta_out + phase)`` (A arcsec, phase deg, theta_out rad), by the
    discrete Fourier sums ``a = 2/N sum TE cos``, ``b = 2/N sum TE sin``."""
    theta = np.radians(np.asarray(output_angle_deg, dtype=float))
    te = np.asarray(te_arcsec, dtype=float)
    a = 2.0 * float(np.mean(te * np.cos(order * theta)))
    b = 2.0 * float(np.mean(te * np.sin(order * theta)))
    return {"order": int(order), "per": "output_rev", "amplitude_arcsec": math.hypot(a, b),
            "phase_deg": _wrap_deg(math.degrees(math.atan2(-b, a)))}


def _finite(value: float, what: str) -> float:
    """``value`` as a float; ValueError ``what, got value`` unless it is finite."""
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{what}, got {value!r}")
    return number


def _wrap_deg(value: float) -> float:
    """An angle in (-180, 180] deg."""
    wrapped = (value + 180.0) % 360.0 - 180.0
    return 180.0 if wrapped == -180.0 else wrapped
