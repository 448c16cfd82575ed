"""Longitudinal actions: speed (absolute, relative, profiles) and longitudinal distance."""

import math

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.xml import child_at
from addt_dsl.plan import ClausePlan
from addt_dsl.runtime.behaviors import PEAK_SLOPE


class Longitudinal:
    @ACTIONS.register("SpeedAction", "approx", "absolute and relative targets, step, linear, cubic and sinusoidal "
                      "shapes over a time (`cruise ... duration`), over a distance (`cruise ... distance`) or "
                      "at a rate (toward the target whichever way), exactly: from the speed the entity has "
                      "when it runs, the Performance bounding the rate; a relative target over a time or a "
                      "distance aims at the reference's speed at the start (W0802)")
    def act_speed(self, speed, who: str, act) -> ClausePlan | None:
        info = self.actors[who]
        relative = child_at(speed, "SpeedActionTarget", "RelativeTargetSpeed")
        if relative is not None:
            return self.relative_speed(speed.find("SpeedActionDynamics"), relative, info)
        target = child_at(speed, "SpeedActionTarget", "AbsoluteTargetSpeed")
        if target is None:
            return self.refuse_inner(act, "absolute and relative speed targets are translated")
        return self.speed_action(speed.find("SpeedActionDynamics"), target, info)

    @ACTIONS.register("SpeedProfileAction", "approx", "`speed_profile` through entries with times; followingMode "
                      "follow as `mode follow` with the DynamicConstraints, exactly; in position mode, slopes "
                      "beyond the DynamicConstraints are not cut (W0802); entries without times and an "
                      "EntityRef are refused")
    def act_speed_profile(self, el, who: str, act) -> ClausePlan | None:
        return self.speed_profile(el, self.actors[who])

    @ACTIONS.register("LongitudinalDistanceAction", "approx", "`keep_gap`; a time gap between reference points "
                      "is kept bumper to bumper (W0802)")
    def act_keep_gap(self, el, who: str, act) -> ClausePlan | None:
        return self.keep_gap(el, who)

    def speed_action(self, dyn, target, info) -> ClausePlan | None:
        v = self.number(target, "value", units.SPEED)
        v_now = float(eval_param_expr(v, self.param_values()))
        shape = self.raw(dyn, "dynamicsShape") if dyn is not None else "step"
        dim = self.raw(dyn, "dynamicsDimension") if dyn is not None else "time"
        amount = abs(self.value(dyn, "value")) if dyn is not None else 0.0
        if shape == "step" or amount == 0.0:
            # At once, as esmini sets it when the action starts.
            info["speed_now"] = v_now
            return ClausePlan(keyword="behavior", name="cruise", settings={"speed": v, "shape": "step"})
        # From the speed the entity has when the action runs (esmini's LongSpeedAction::Start;
        # the importer's `speed_now` misses what conditions, synchronisations, teleports and
        # road ends did before), whichever way that is from the target: over a time T; at a
        # rate, toward the target at it; over a distance d, in 2 d / (v0 + v1). Each takes
        # longer only where the peak rate exceeds the vehicle's Performance
        # (TransitionDynamics::SetMaxRate). With no difference a change over a time still runs
        # for T and completes, as `ended(step)` waits; over a distance it is a step.
        info["speed_now"] = v_now
        settings = {"speed": v, **self.speed_dynamics(dyn)}
        if dim == "time":
            settings.setdefault("shape", "linear")
        settings.update({k: E.Num(value=info[k]) for k in ("max_accel", "max_decel") if info.get(k)})
        return ClausePlan(keyword="behavior", name="cruise", settings=settings)

    def speed_profile(self, el, info) -> ClausePlan | None:
        entries = list(el.iterfind("SpeedProfileEntry"))
        if not entries or any(e.get("time") is None for e in entries):
            self.skip(el, "a speed profile without entry times is not translated",
                      "`speed_profile` needs the time of each point")
            return None
        # Entry times are durations from the previous entry: cumulative times from the start.
        gaps = [max(self.value(e, "time"), 0.0) for e in entries]
        times = [units.decimal_sum(gaps[:k + 1]) for k in range(len(gaps))]  # 0.1 + 0.2 is 0.3
        if any(b <= a for a, b in zip(times, times[1:])):
            self.skip(el, "a speed profile whose entries take no time is not translated")
            return None
        if el.find("EntityRef") is not None:
            self.skip(el.find("EntityRef"), "a speed profile relative to another entity's speed is not translated")
            return None
        speeds = [self.value(e, "speed") for e in entries]
        settings = {"times": [E.Num(value=x) for x in times], "speeds": [E.Num(value=v) for v in speeds]}
        limits = self.dynamic_constraints(el.find("DynamicConstraints"), info)
        if el.get("followingMode") == "follow":
            settings["mode"] = "follow"
            settings.update({k: E.Num(value=v) for k, v in limits.items()})
        else:
            # esmini cuts a slope beyond the limits (its entry comes later) in position mode too.
            slopes = [(b - a) / dt for a, b, dt in zip([info["speed_now"]] + speeds, speeds,
                                                       [times[0]] + [y - x for x, y in zip(times, times[1:])]) if dt]
            if any(k > limits.get("accel", math.inf) or -k > limits.get("decel", math.inf) for k in slopes):
                self.approx(el, "a slope beyond the DynamicConstraints in followingMode position: met as given "
                                "(esmini cuts it to the limit and meets the entry later)")
        info["speed_now"] = speeds[-1]
        return ClausePlan(keyword="behavior", name="speed_profile", settings=settings)

    def dynamic_constraints(self, dc, info) -> dict[str, float]:
        """DynamicConstraints as `speed_profile` limits, as esmini reads them: an attribute left
        out is the vehicle's Performance (rates: unlimited), one above it is cut to it, one
        below 1e-6 is replaced by the smaller of esmini's default and the Performance; no
        element: unlimited (no setting)."""
        if dc is None:
            return {}
        out = {}
        for attr, key, perf_key, default, dim in (
                ("maxAcceleration", "accel", "max_accel", 5.0, units.ACCELERATION),
                ("maxDeceleration", "decel", "max_decel", 10.0, units.ACCELERATION),
                ("maxAccelerationRate", "accel_rate", None, math.inf, units.JERK),
                ("maxDecelerationRate", "decel_rate", None, math.inf, units.JERK),
                ("maxSpeed", "max_speed", "max_speed", units.to_si(250.0, "km/h")[0], units.SPEED)):
            perf = info.get(perf_key, math.inf) if perf_key else math.inf
            value = perf if dc.get(attr) is None else self.value(dc, attr, dim)
            if value < 1e-6:
                value = min(default, perf)
            value = min(value, perf)
            if math.isfinite(value):
                out[key] = value
        return out

    def relative_speed(self, dyn, rel, info) -> ClausePlan | None:
        ref = self.actor_name(rel)
        if ref is None:
            return None
        value = self.value(rel, "value")
        kind = rel.get("speedTargetValueType", "delta")
        if rel.get("continuous", "false") not in ("true", "1"):
            self.approx(rel, "a relative speed target that is not continuous: followed continuously")
        other = E.Signal(name=f"speed({ref})")
        if kind == "factor":
            speed = E.Binary(op="*", left=E.Num(value=value), right=other)
        elif value:
            speed = E.Binary(op="+", left=other, right=E.Num(value=value))
        else:
            speed = other
        settings = {"speed": speed}
        if dyn is not None:
            settings.update(self.speed_dynamics(dyn))
            # From the speed the entity has when it runs, stretched to the vehicle's
            # Performance as esmini does (TransitionDynamics::SetMaxRate).
            settings.update({k: E.Num(value=info[k]) for k in ("max_accel", "max_decel") if info.get(k)})
        if "duration" in settings or "distance" in settings:
            over = "time" if "duration" in settings else "distance"
            self.approx(dyn, f"a relative target over a {over}: the change aims at the reference's speed when it "
                             "starts and follows it once reached (esmini aims at its speed at each step)")
        return ClausePlan(keyword="behavior", name="cruise", settings=settings)

    def speed_dynamics(self, dyn) -> dict:
        """Shape and rate/duration of a speed change as `cruise` settings (rate: the peak rate
        of change, as esmini reads it: TransitionDynamics::GetTargetParamValByPrimPeak)."""
        shape = self.raw(dyn, "dynamicsShape")
        dim = self.raw(dyn, "dynamicsDimension")
        amount = abs(self.value(dyn, "value"))
        if shape not in PEAK_SLOPE or shape == "quintic":
            self.approx(dyn, f"dynamics shape {shape}: linear")
            shape = "linear"
        out = {"shape": shape} if shape != "linear" else {}
        if shape == "step":
            return out
        if dim == "time":
            out["duration"] = E.Num(value=amount)
        elif dim == "rate":
            rate = max(amount, 0.01)
            out.update(accel=E.Num(value=rate), decel=E.Num(value=rate))
        elif dim == "distance":
            out["distance"] = E.Num(value=amount)
        else:
            self.approx(dyn, f"a speed change over a {dim}: at the default rate limits")
        return out

    def keep_gap(self, el, who: str) -> ClausePlan | None:
        ref = self.actor_name(el)
        if ref is None:
            return None
        settings = {"target": ref}
        if el.get("distance") is not None:
            settings["distance"] = E.Num(value=self.value(el, "distance"))
        elif el.get("timeGap") is not None:
            settings["time_gap"] = E.Num(value=self.value(el, "timeGap"))
        else:
            self.error(el, "a LongitudinalDistanceAction needs a distance or a timeGap")
            return None
        if el.get("displacement") == "leadingReferencedEntity":
            settings["side"] = "ahead"
        limits = el.find("DynamicConstraints")
        for attr, key in (("maxAcceleration", "accel"), ("maxDeceleration", "decel")):
            src = el if el.get(attr) is not None else limits
            if src is not None and src.get(attr) is not None:
                settings[key] = E.Num(value=max(self.value(src, attr), 0.01))
        if el.get("freespace") in ("false", "0"):
            if "distance" in settings:  # between reference points (the actors' centres here)
                half = 0.5 * (self.size(who)[0] + self.size(ref)[0])
                settings["distance"] = E.Num(value=max(settings["distance"].value - half, 0.0))
            else:
                self.approx(el, "a time gap between reference points: kept as a bumper-to-bumper gap")
        return ClausePlan(keyword="behavior", name="keep_gap", settings=settings)
