"""The time-domain engine of the simulated gear unit (single-threaded; GearPlant wraps it).

Mechanics (docs/plant.md): the loading drive's torque ``T_d`` (first-order loop, time constant
``tau_d``, clipped at the torque limit) turns the output inertia ``J``; the output twist
``phi`` (rad, output angle minus the kinematic ``-input / ratio``) is held by the unit:

    J phi'' = T_d - G(phi) - F_f,

``G`` the torque of the elastic chain (mesh with its free play, stiffening, shaft compliance,
bearing clearance, creep: all in series) and ``F_f`` the output friction (Dahl/LuGre,
parallel). The chain is written through its compliance ``phi = c + s (play / 2 + h(|G|))``
for ``G != 0`` (``s`` the flank), zero torque inside the play.

Integration: fixed steps of implicit (backward) Euler. The step's end twist solves one
scalar equation ``J (phi - phi_pred) / dt^2 + F_f(phi) + G(phi) - T_d = 0`` whose left side
is monotone in ``phi``: its root is unique and found by safeguarded Newton (bisection
fallback), in the free-play regime or, on a flank, with the flank torque as unknown.
Unconditionally stable for the stiff mesh (~28 N*m/arcmin, ~350 Hz with J = 0.02 kg m^2)
and deterministic. Drive, housing temperature and creep are first-order lags updated
exactly over the step.
"""

from __future__ import annotations

import math

from simulators.plant.config import PlantConfig
from simulators.plant.friction import Friction
from simulators.plant.geometry import ARCMIN_PER_RAD
from simulators.plant.implicit_step import Compliance, StepResult, solve_step
from simulators.plant.kinds import geometry_for


class PlantModel:
    """State and fixed-step integration of the plant. Not thread-safe (GearPlant locks)."""

    def __init__(self, config: PlantConfig) -> None:
        self.config = config
        self.geometry = geometry_for(config)
        rig, fx = config.rig, config.effects
        geo = self.geometry
        self.ratio = geo.ratio
        self.mesh_stiffness_Nm_per_rad = geo.nominal.stiffness_Nm_per_arcmin * ARCMIN_PER_RAD
        c_lin = 1.0 / self.mesh_stiffness_Nm_per_rad
        if fx.shaft_compliance.enabled:
            c_lin += 1.0 / (fx.shaft_compliance.stiffness_Nm_per_arcmin * ARCMIN_PER_RAD)
        sn, bc = fx.stiffness_nonlinearity, fx.bearing_clearance
        self.compliance = Compliance(
            c_lin=c_lin,
            soft_rad=sn.soft_twist_arcmin / ARCMIN_PER_RAD if sn.enabled else 0.0,
            soft_scale_Nm=sn.torque_scale_Nm,
            bearing_c=1.0 / (bc.soft_stiffness_Nm_per_arcmin * ARCMIN_PER_RAD) if bc.enabled
            else 0.0,
            bearing_torque_Nm=bc.soft_stage_torque_Nm if bc.enabled else 0.0,
            stages=geo.mesh_stiffening,
        )
        self.creep_c = (1.0 / (fx.creep.stiffness_Nm_per_arcmin * ARCMIN_PER_RAD)
                        if fx.creep.enabled else 0.0)
        self.creep_tau_s = fx.creep.time_constant_s
        self.friction = Friction.from_config(fx.friction) if fx.friction.enabled else None
        self.dt = rig.step_s
        self.inertia = rig.inertia_kgm2
        self.limit_Nm = rig.drive_torque_limit_Nm
        # state
        self.t_s = 0.0
        self.command_Nm = 0.0
        self.enabled = True
        self.drive_Nm = 0.0
        self.temperature_C = config.housing.initial_C
        self.ambient_C = config.housing.ambient_C
        self.input_deg = rig.initial_input_angle_deg
        self.input_target_deg = self.input_deg
        self.input_speed_deg_s = rig.input_speed_deg_per_s
        """How fast the input moves toward its target (deg/s): the positioning speed, or the
        speed of a constant-speed turn (then the target is +-inf)."""
        self.encoder_ecc_deg = rig.encoder_eccentricity_arcsec / 3600.0
        self.encoder_ecc_phase_rad = math.radians(rig.encoder_eccentricity_phase_deg)
        self.creep_rad = 0.0
        self.velocity = 0.0
        self.chain_Nm = 0.0
        self.flange_Nm = 0.0
        self._geo_deg = math.nan
        self._geo_play_um = 0.0
        self._geo_pitch_rad = 0.0
        self._play_key: tuple[float, float] | None = None
        self._play_value = 0.0
        self._decay_cache: dict[float, tuple[float, float, float]] = {}
        self.twist_rad = 0.0
        # the rig's dynamics (docs/plant.md, [rig] contact_damping_ratio, drive ripple) and the
        # torque sensor's first-order lag ([measurement] torque_lag_s)
        self.zeta = rig.contact_damping_ratio
        self.omega_locked = math.sqrt(1.0 / (c_lin * self.inertia))
        self.ripple_Nm, self.ripple_Hz = rig.drive_ripple_Nm, rig.drive_ripple_Hz
        self.sensor_lag_s = config.measurement.torque_lag_s
        self.sensor_Nm = 0.0
        self.accel = 0.0
        self._ring_left_s = 0.0
        self.impacts = 0
        self.settle_at_rest(rig.start_flank)

    # -- geometry --------------------------------------------------------------------------
    def _refresh_geometry(self) -> None:
        if self.input_deg != self._geo_deg:
            geo = self.geometry
            self._geo_deg = self.input_deg
            self._geo_play_um = (geo.base_play_um(self.input_deg)
                                 + geo.runout_play_um(self.input_deg)
                                 + geo.spacing_play_um(self.input_deg))
            self._geo_pitch_rad = (geo.arcmin_from_um(
                geo.pitch_offset_um(self.input_deg) + geo.kinematic_error_um(self.input_deg))
                / ARCMIN_PER_RAD)

    def mesh_play_um(self) -> float:
        """Circumferential play of the mesh now (um, >= 0)."""
        self._refresh_geometry()
        thermal = self.geometry.thermal_play_um(self.temperature_C)
        return max(self._geo_play_um + thermal, 0.0)

    def play_rad(self) -> float:
        """Total dead zone (mesh + bearing clearance) as an output angle (rad)."""
        key = (self.input_deg, self.temperature_C if self.geometry.thermal_um_per_K else 0.0)
        if key != self._play_key:
            j_t = self.mesh_play_um() + self.geometry.bearing_play_um
            self._play_value = self.geometry.arcmin_from_um(j_t) / ARCMIN_PER_RAD
            self._play_key = key
        return self._play_value

    def pitch_offset_rad(self) -> float:
        """Shift of both flanks (rad): the tooth pitch deviations and the kinematic error
        of the eccentricities (geometry.kinematic_error_um)."""
        self._refresh_geometry()
        return self._geo_pitch_rad

    # -- the scalar solve ------------------------------------------------------------------
    def solve(self, drive_Nm: float, mass: float, phi_pred: float, centre: float,
              half_play: float, compliance: Compliance) -> StepResult:
        """End twist of a step from the current twist and chain torque
        (:func:`simulators.plant.implicit_step.solve_step`).

        ``mass`` = J / dt^2 (0: quasi-static). Friction must have had begin_step. Returns
        (phi, chain torque G, friction torque, new bristle force)."""
        return solve_step(self.friction, self.twist_rad, self.chain_Nm, drive_Nm, mass,
                          phi_pred, centre, half_play, compliance)

    # -- stepping --------------------------------------------------------------------------
    def drive_target_Nm(self) -> float:
        """What the drive's torque loop follows: the clipped command, or 0 when disabled."""
        if not self.enabled:
            return 0.0
        return min(max(self.command_Nm, -self.limit_Nm), self.limit_Nm)

    def is_quiescent(self) -> bool:
        """At rest: drive settled, output still, input not turning (long steps are safe)."""
        target = self.drive_target_Nm()
        return (abs(self.drive_Nm - target) <= 1e-9 * (1.0 + abs(target))
                and abs(self.velocity) < 1e-6 and self.input_deg == self.input_target_deg)

    def _decays(self, dt: float) -> tuple[float, float, float]:
        """exp(-dt / tau) of the drive, housing and creep lags (cached per step size)."""
        cached = self._decay_cache.get(dt)
        if cached is None:
            cfg = self.config
            cached = (math.exp(-dt / cfg.rig.drive_time_constant_s),
                      math.exp(-dt / cfg.housing.time_constant_s),
                      math.exp(-dt / self.creep_tau_s))
            if len(self._decay_cache) < 64:
                self._decay_cache[dt] = cached
        return cached

    def step(self, dt: float, count: int = 1) -> None:
        """Advance by ``count`` steps of ``dt`` s (implicit Euler for the output; exact lags
        for drive, housing temperature and creep). The loop keeps its state in locals.

        With the rig's dynamics on (contact damping, drive ripple, sensor lag) steps of at
        most 10 integration steps go through :meth:`_step_dynamic` (impacts ring); a long
        step at rest stays one implicit step."""
        if (self.zeta > 0.0 or self.ripple_Nm > 0.0) and dt <= 10.0 * self.dt:
            for _ in range(count):
                self._step_dynamic(dt)
            return
        self._step_euler(dt, count)
        self._lag_sensor(dt * count)

    def _lag_sensor(self, dt: float) -> None:
        """The torque sensor's first-order lag (exact for a flange torque constant over dt)."""
        if self.sensor_lag_s > 0.0:
            a = math.exp(-dt / self.sensor_lag_s)
            self.sensor_Nm = self.flange_Nm + (self.sensor_Nm - self.flange_Nm) * a
        else:
            self.sensor_Nm = self.flange_Nm

    def _ripple(self, t_s: float) -> float:
        """Drive torque ripple (N*m) at time ``t_s``: a sine of drive_ripple_Nm at
        drive_ripple_Hz while the drive is enabled."""
        if not self.ripple_Nm or not self.enabled:
            return 0.0
        return self.ripple_Nm * math.sin(2.0 * math.pi * self.ripple_Hz * t_s)

    # Newmark (gamma, beta) of the impact sub-steps: unconditionally stable, damps what the
    # sub-step cannot resolve (the friction bristles), numerical damping ratio about
    # (gamma - 1/2) omega h / 2 at the locked resonance, taken off the contact damper.
    _GAMMA, _BETA = 0.6, 0.3025
    _OMEGA_H = 0.35  # omega_locked * sub-step
    _RING_TIME_CONSTANTS = 3.0  # sub-step until 3 / (zeta omega) after the last impact
    _RING_MIN_NM = 0.005  # impacts that ring less than this (N*m) stay implicit Euler steps

    def _snapshot_state(self) -> tuple:
        fr = self.friction
        return (self.t_s, self.drive_Nm, self.twist_rad, self.velocity, self.creep_rad,
                self.chain_Nm, self.flange_Nm, self.accel, self.temperature_C, self.input_deg,
                None if fr is None else fr.bristle_Nm)

    def _restore_state(self, st: tuple) -> None:
        (self.t_s, self.drive_Nm, self.twist_rad, self.velocity, self.creep_rad,
         self.chain_Nm, self.flange_Nm, self.accel, self.temperature_C, self.input_deg,
         bristle) = st
        if self.friction is not None:
            self.friction.bristle_Nm = bristle

    def _step_dynamic(self, dt: float) -> None:
        """One step of ``dt`` with impacts resolved. A step that starts in the free play, or
        on a flank with no impact ringing, is an implicit Euler step; when such a step takes
        the output from the free play onto a flank at a speed that rings (``J omega v >=
        _RING_MIN_NM``), it is done again in Newmark sub-steps of ``_OMEGA_H / omega`` with
        the contact damper ``2 zeta sqrt(K J)`` (K the locked chain stiffness), and so are
        the steps on a flank after it until the ringing has decayed
        (``_RING_TIME_CONSTANTS / (zeta omega)``; a bounce that comes back restarts it)."""
        ringing = self.zeta > 0.0 and self._ring_left_s > 0.0
        was_free = self.chain_Nm == 0.0
        if not ringing or was_free:
            saved = self._snapshot_state()
            # the ringing an impact at this speed starts: J omega v (N*m); a contact that
            # merely flickers at rest (ripple at zero torque) rings below the sensor noise
            ring_Nm = self.inertia * self.omega_locked * abs(self.velocity)
            self._euler_with_ripple(dt)
            if not (self.zeta > 0.0 and was_free and self.chain_Nm != 0.0
                    and ring_Nm >= self._RING_MIN_NM):
                self._lag_sensor(dt)
                self._ring_left_s -= dt
                return
            self._restore_state(saved)
            self._ring_left_s = self._ring_window_s()
            self.impacts += 1
            self.accel = (self.drive_Nm + self._ripple(self.t_s) - self.flange_Nm) / self.inertia
        n = max(1, math.ceil(dt * self.omega_locked / self._OMEGA_H))
        h = dt / n
        for _ in range(n):
            free = self.chain_Nm == 0.0
            self._newmark_substep(h)
            self._lag_sensor(h)
            if free and self.chain_Nm != 0.0:
                self._ring_left_s = self._ring_window_s()
        self._ring_left_s -= dt

    def _ring_window_s(self) -> float:
        return min(self._RING_TIME_CONSTANTS / (self.zeta * self.omega_locked), 0.2)

    def _euler_with_ripple(self, dt: float) -> None:
        """One implicit Euler step with the drive ripple held over it."""
        self._step_euler(dt, 1, self._ripple(self.t_s + dt))

    def _newmark_substep(self, h: float) -> None:
        """One Newmark sub-step of ``h`` s: ``J phi'' = T_d + ripple - c phi' [contact] - G -
        F_f`` with ``phi = phi_pred + beta h^2 phi''`` solved by :meth:`solve` (the same
        monotone scalar root as the implicit Euler step, with mass ``J / (beta h^2)``)."""
        g, b = self._GAMMA, self._BETA
        target = self.drive_target_Nm()
        self.drive_Nm = target + (self.drive_Nm - target) * math.exp(
            -h / self.config.rig.drive_time_constant_s)
        if self.input_deg != self.input_target_deg:
            move = self.input_speed_deg_s * h
            diff = self.input_target_deg - self.input_deg
            self.input_deg = self.input_target_deg if abs(diff) <= move else (
                self.input_deg + math.copysign(move, diff))
        if self.temperature_C != self.ambient_C:
            a_temp = math.exp(-h / self.config.housing.time_constant_s)
            self.temperature_C = self.ambient_C + (self.temperature_C - self.ambient_C) * a_temp
        omega_h = self.omega_locked * h
        zeta_c = max(self.zeta - 0.5 * (g - 0.5) * omega_h, 0.0)
        damper = 2.0 * zeta_c * self.omega_locked * self.inertia  # N*m*s/rad
        phi, vel, acc = self.twist_rad, self.velocity, self.accel
        drive = self.drive_Nm + self._ripple(self.t_s + h)
        if self.chain_Nm != 0.0:
            drive -= damper * vel
        mass = self.inertia / (b * h * h)
        phi_pred = phi + h * vel + h * h * (0.5 - b) * acc
        centre = self.pitch_offset_rad() + self.creep_rad
        half = 0.5 * self.play_rad()
        if self.friction is not None:
            self.friction.begin_step(vel, h)
        phi_new, chain, fric, bristle = self.solve(drive, mass, phi_pred, centre, half,
                                                   self.compliance)
        if self.friction is not None:
            self.friction.commit(bristle)
        acc_new = (phi_new - phi_pred) / (b * h * h)
        self.velocity = vel + h * ((1.0 - g) * acc + g * acc_new)
        self.accel = acc_new
        self.twist_rad = phi_new
        self.chain_Nm, self.flange_Nm = chain, chain + fric
        if self.creep_c:
            goal = chain * self.creep_c
            self.creep_rad = goal + (self.creep_rad - goal) * math.exp(-h / self.creep_tau_s)
        self.t_s += h

    def _step_euler(self, dt: float, count: int = 1, ripple_Nm: float = 0.0) -> None:
        """``count`` implicit Euler steps of ``dt`` s (see :meth:`step`); ``ripple_Nm`` is
        added to the drive's torque over them (it shifts the loop's target and state alike,
        so the lag itself is unchanged)."""
        a_drive, a_temp, a_creep = self._decays(dt)
        mass = self.inertia / (dt * dt)
        fr = self.friction
        solve = self.solve
        compliance = self.compliance
        creep_c = self.creep_c
        thermal = bool(self.geometry.thermal_um_per_K)
        # frictionless, piecewise-linear chain: closed-form flank torque (compliance.invert)
        linear = fr is None and not compliance.soft_rad and not compliance.stages
        c_lin, c_b, t_b = compliance.c_lin, compliance.bearing_c, compliance.bearing_torque_Nm
        target = self.drive_target_Nm() + ripple_Nm
        drive, temp, amb = self.drive_Nm + ripple_Nm, self.temperature_C, self.ambient_C
        phi, vel, creep = self.twist_rad, self.velocity, self.creep_rad
        chain = fric = 0.0
        pitch, half = self.pitch_offset_rad(), 0.5 * self.play_rad()
        for _ in range(count):
            refresh = False
            if self.input_deg != self.input_target_deg:
                move = self.input_speed_deg_s * dt
                diff = self.input_target_deg - self.input_deg
                self.input_deg = self.input_target_deg if abs(diff) <= move else (
                    self.input_deg + math.copysign(move, diff))
                refresh = True
            drive = target + (drive - target) * a_drive
            if temp != amb:
                temp = amb + (temp - amb) * a_temp
                self.temperature_C = temp
                refresh = refresh or thermal
            if refresh:
                pitch, half = self.pitch_offset_rad(), 0.5 * self.play_rad()
            centre = pitch + creep
            phi_pred = phi + vel * dt
            if linear:
                phi_new = phi_pred + drive / mass
                if phi_new > centre + half:
                    side = 1.0
                elif phi_new < centre - half:
                    side = -1.0
                else:
                    side = 0.0
                    chain = 0.0
                if side:
                    base = centre + side * half
                    q = side * (drive - mass * (base - phi_pred))
                    tau = q / (mass * (c_lin + c_b) + 1.0)
                    if c_b and tau > t_b:
                        tau = (q - mass * c_b * t_b) / (mass * c_lin + 1.0)
                        phi_new = base + side * (tau * c_lin + t_b * c_b)
                    else:
                        phi_new = base + side * tau * (c_lin + c_b)
                    chain = side * tau
            else:
                self.twist_rad, self.chain_Nm = phi, chain
                if fr is not None:
                    fr.begin_step(vel, dt)
                phi_new, chain, fric, bristle = solve(drive, mass, phi_pred, centre, half,
                                                      compliance)
                if fr is not None:
                    fr.commit(bristle)
            vel = (phi_new - phi) / dt
            phi = phi_new
            if creep_c:
                goal = chain * creep_c
                creep = goal + (creep - goal) * a_creep
        self.drive_Nm, self.twist_rad, self.velocity, self.creep_rad = (
            drive - ripple_Nm, phi, vel, creep)
        self.chain_Nm, self.flange_Nm = chain, chain + fric
        self.t_s += dt * count

    # -- quasi-static ----------------------------------------------------------------------
    def quasi_static_compliance(self) -> Compliance:
        """The chain's compliance in the infinitely slow limit (creep fully developed)."""
        c = self.compliance
        return Compliance(c.c_lin + self.creep_c, c.soft_rad, c.soft_scale_Nm, c.bearing_c,
                          c.bearing_torque_Nm, c.stages)

    def quasi_static_path(self, torques_Nm, start_flank: int) -> list[float]:
        """Twists (rad) along a slow torque path, from rest on ``start_flank`` (state kept)."""
        compliance = self.quasi_static_compliance()
        centre = self.pitch_offset_rad()
        half = 0.5 * self.play_rad()
        self.creep_rad = 0.0
        self._rest_on_flank(start_flank, centre, half, compliance)
        out = []
        for torque in torques_Nm:
            out.append(self._qs_step(float(torque), centre, half, compliance))
        return out

    def _qs_step(self, torque: float, centre: float, half: float, compliance: Compliance) -> float:
        if self.friction is not None:
            self.friction.begin_step(0.0, None)
        phi, chain, fric, bristle = self.solve(torque, 0.0, 0.0, centre, half, compliance)
        self.twist_rad, self.chain_Nm, self.flange_Nm = phi, chain, chain + fric
        if self.friction is not None:
            self.friction.commit(bristle)
        return phi

    def _rest_on_flank(self, flank: int, centre: float, half: float,
                       compliance: Compliance) -> None:
        """Rest at zero torque after a preload to ``flank * preload`` (the GB/T start)."""
        self.twist_rad, self.chain_Nm = centre + flank * half, 0.0
        if self.friction is not None:
            self.friction.bristle_Nm = 0.0
        preload = self.config.rig.preload_torque_Nm
        if preload > 0.0:
            self._qs_step(flank * preload, centre, half, compliance)
            self._qs_step(0.0, centre, half, compliance)
        self.velocity = 0.0

    def settle_at_rest(self, flank: int) -> None:
        """Put the output at rest at zero drive torque on ``flank`` (-1 or +1)."""
        self.drive_Nm = 0.0
        self.creep_rad = 0.0
        self._rest_on_flank(flank, self.pitch_offset_rad(), 0.5 * self.play_rad(),
                            self.compliance)
        self.flange_Nm = self.chain_Nm + (self.friction.bristle_Nm if self.friction else 0.0)
        self.flange_Nm = 0.0 if abs(self.flange_Nm) < 1e-12 else self.flange_Nm
        self.sensor_Nm = self.flange_Nm
        self.accel = 0.0

    # -- readings --------------------------------------------------------------------------
    def output_angle_deg(self) -> float:
        """Output encoder angle (deg), noise-free: offset - input / ratio + twist, plus the
        encoder's mounting eccentricity ``E sin(theta_out + phase)`` (a reading error)."""
        angle = (self.config.rig.output_offset_deg - self.input_deg / self.ratio
                 + math.degrees(self.twist_rad))
        if self.encoder_ecc_deg:
            angle += self.encoder_ecc_deg * math.sin(math.radians(angle)
                                                     + self.encoder_ecc_phase_rad)
        return angle

    def sensor_torque_Nm(self, true_Nm: float) -> float:
        """The torque channel without noise: direction gain and offset applied."""
        fx = self.config.effects
        value = true_Nm
        if fx.direction_gain.enabled:
            dg = fx.direction_gain
            value *= dg.gain_positive if true_Nm >= 0.0 else dg.gain_negative
        if fx.torque_sensor_offset.enabled:
            value += fx.torque_sensor_offset.offset_Nm
        return value
