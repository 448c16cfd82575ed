"""Global actions: the environment and traffic signals (controllers, phases, states)."""

import math
import re
from datetime import datetime

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.interop.openscenario.entities import safe_name
from addt_dsl.interop.openscenario.xml import child_at
from addt_dsl.interop.xosc_export import lamps_of, state_of_lamps
from addt_dsl.plan import LIGHT_PROGRAM, LIGHT_STATES, ClausePlan


class Global:
    def environment_models(self, env) -> list[ClausePlan]:
        """The models an <Environment> sets: fog, rain, the light (the sun's elevation, or a
        time of day) and the road's friction scale. What the twin has no model for is said
        (W0802)."""
        out: list[ClausePlan] = []
        weather = env.find("Weather")
        road = env.find("RoadCondition")
        if road is not None and road.get("frictionScaleFactor") is not None:
            scale = min(max(self.value(road, "frictionScaleFactor"), 0.05), 2.0)
            out.append(ClausePlan(keyword="environment", name="road", settings={"friction": E.Num(value=scale)}))
        if road is not None and (road.find("Properties") is not None or road.get("wetness") is not None):
            self.approx(road, "road wetness and properties: no model (rain, fog, light are)")
        if weather is None and env.find("TimeOfDay") is None:
            if not out:
                self.approx(env, "an environment without weather or time of day: clear daylight")
            return out
        weather = weather if weather is not None else env.makeelement("Weather", {})
        fog, rain, sun = weather.find("Fog"), weather.find("Precipitation"), weather.find("Sun")
        unmodelled = [f"<{el.tag}>" for el in (weather.find("Wind"), weather.find("DomeImage")) if el is not None]
        unmodelled += [a for a in ("fractionalCloudCover", "cloudState", "temperature", "atmosphericPressure")
                       if weather.get(a) is not None]
        if unmodelled:
            self.approx(weather, f"{', '.join(unmodelled)}: no model (the sensors see fog, rain and light only)")
        if fog is not None:
            visibility = min(max(self.value(fog, "visualRange"), 10.0), 100000.0)
            out.append(ClausePlan(keyword="environment", name="fog", settings={"visibility": E.Num(value=visibility)}))
        if rain is not None and rain.get("precipitationType") == "rain":
            intensity = rain.get("precipitationIntensity") or rain.get("intensity")
            if intensity is not None:
                rate = min(float(self.resolve(intensity)), 200.0) * units.lookup("mm/h").factor
                # Rain that stops: a rate of 0 leaves the lidar as clear air does.
                out.append(ClausePlan(keyword="environment", name="rain", settings={"rate": E.Num(value=rate)}))
        elif rain is not None and rain.get("precipitationType") == "dry":
            out.append(ClausePlan(keyword="environment", name="rain", settings={"rate": E.Num(value=0.0)}))
        elif rain is not None and rain.get("precipitationType") is not None:
            self.approx(rain, f"precipitation {rain.get('precipitationType')}: no model (rain, fog, light are)")
        light = self.light_model(env.find("TimeOfDay"), sun)
        if light is not None:
            out.append(light)
        return out

    def light_model(self, time_of_day, sun) -> ClausePlan | None:
        """`light sun E` from a Sun's elevation, else `light time T day D` from a TimeOfDay's
        local time and date (the latitude: the language's default, said)."""
        if sun is not None and sun.get("elevation") is not None:
            if time_of_day is not None:
                self.approx(time_of_day, "a time of day beside the sun's elevation: the elevation is used")
            elevation = min(max(self.value(sun, "elevation"), -math.pi / 2), math.pi / 2)
            return ClausePlan(keyword="environment", name="light", settings={"sun": E.Num(value=elevation)})
        if time_of_day is None:
            return None
        text = self.raw(time_of_day, "dateTime")
        try:
            when = datetime.fromisoformat(text)
        except ValueError:
            self.error(time_of_day, f"dateTime \"{text[:40]}\" is not an ISO 8601 date and time")
            return None
        seconds = when.hour * 3600.0 + when.minute * 60.0 + when.second + when.microsecond * 1e-6
        self.approx(time_of_day, "a time of day: the sun's elevation at that local time and date, at latitude "
                                 "45 deg (OpenSCENARIO gives no place); `animation` (the clock running) is not "
                                 "translated")
        return ClausePlan(keyword="environment", name="light",
                          settings={"time": E.Num(value=seconds), "day": E.Num(value=float(when.timetuple().tm_yday))})

    def environment_action(self, env) -> None:
        """An EnvironmentAction in Init: the run's conditions from the start."""
        for model in self.environment_models(env):
            self.environment = [m for m in self.environment if m.name != model.name] + [model]

    # -- traffic lights

    def signal_state(self, sid: str, text: str, el) -> str | None:
        """green, yellow or red shown by signal `sid` in state `text` (its lamps from the map's
        signal type); None after a diagnostic."""
        found = self.network.signal(sid)
        if found is None:
            self.skip(el, f"{self.xodr_name} has no signal '{sid}'",
                      f"traffic lights on the map: {', '.join(self.network.signal_ids(dynamic_only=True)) or '(none)'}")
            return None
        lamps = lamps_of(found[1].type, found[1].subtype)
        state = state_of_lamps(lamps, text)
        if state is None:
            self.skip(el, f"state '{text}' of signal {sid} shows no one colour of its lamps ({';'.join(lamps)})",
                      "translated: one lamp on or flashing, or a word green, yellow (amber), red")
        return state

    def signal_controller(self, ctl) -> None:
        """A TrafficSignalController: its phases as one green -> yellow -> red cycle (phases in
        a rotation of that order: the offset is where the cycle's first colour starts). A
        phase's colour is its first signal's."""
        name = safe_name(self.raw(ctl, "name"), set(self.light_ctls))
        self.ctl_names.setdefault(self.raw(ctl, "name"), name)
        phases, signals = [], []
        for phase in ctl.iterfind("Phase"):
            states = list(phase.iterfind("TrafficSignalState"))
            for st in states:
                sid = self.raw(st, "trafficSignalId")
                if sid not in signals and self.network.signal(sid) is not None:
                    signals.append(sid)
            state = self.signal_state(self.raw(states[0], "trafficSignalId"), self.raw(states[0], "state"),
                                      states[0]) if states else None
            if state is None:
                state = {"amber": "yellow"}.get((phase.get("name") or "").lower(), (phase.get("name") or "").lower())
                if state not in LIGHT_STATES:
                    self.approx(phase, f"phase '{phase.get('name')}' shows no traffic-light colour: read as red")
                    state = "red"
            phases.append((self.raw(phase, "name"), state, self.value(phase, "duration", units.TIME)))
        if ctl.get("delay") is not None or ctl.get("reference") is not None:
            self.skip(ctl, "a controller's delay to a reference controller is not translated: its phases start at 0 s")
        if not signals:
            self.skip(ctl, f"controller '{name}' switches no signal of {self.xodr_name}: not translated")
            return
        # Sums of the file's decimals, exactly (phases of 0.1 s and 0.2 s make a 0.3 s cycle).
        cycle = {k: units.decimal_sum(d for _, st, d in phases if st == k) for k in ("green", "yellow", "red")}
        total = units.decimal_sum(d for _, _, d in phases)
        timed = [(st, d) for _, st, d in phases if d > 0]
        # Runs of one colour, the last joined to the first when they match (the cycle repeats).
        runs = [st for i, (st, _) in enumerate(timed) if i == 0 or timed[i - 1][0] != st]
        if len(runs) > 1 and runs[0] == runs[-1]:
            runs.pop()
        wanted = [k for k in ("green", "yellow", "red") if cycle[k] > 0]
        offset = 0.0
        if runs and any(runs[i:] + runs[:i] == wanted for i in range(len(runs))):
            # The language's program starts its first colour at the offset: where that run starts.
            lead = wanted[0]
            i = next(i for i, (st, _) in enumerate(timed) if st == lead and timed[i - 1][0] != lead) \
                if len(timed) > 1 else 0
            offset = units.decimal_sum(d for _, d in timed[:i]) % total if total > 0 else 0.0
        elif timed:
            self.approx(ctl, f"controller '{name}': phases {', '.join(st for st, _ in timed)} as one green, "
                             "yellow, red cycle of their summed times")
        exact = ((self.sidecar or {}).get("lights") or {}).get("controllers", {}).get(name)
        if exact:  # the export's program exactly (its offset has no OpenSCENARIO form)
            cycle = {k: float(exact[f"{k}_s"]) for k in cycle}
            offset = float(exact["offset_s"])
        self.light_ctls[name] = {"signals": signals, "el": ctl, "offset": offset,
                                 "phases": {pname: st for pname, st, _ in phases}, **cycle}
        for sid in signals:
            self.signal_owner.setdefault(sid, name)

    def light_controller(self, sid: str, el) -> str | None:
        """The controller that switches signal `sid`: the file's, or one of its own (a signal
        set directly, as esmini's files do: `controller signal_N signals [N]`)."""
        if sid in self.signal_owner:
            return self.signal_owner[sid]
        if self.network.signal(sid) is None:
            self.skip(el, f"{self.xodr_name} has no signal '{sid}'",
                      f"traffic lights on the map: {', '.join(self.network.signal_ids(dynamic_only=True)) or '(none)'}")
            return None
        name = safe_name(f"signal_{sid}" if re.fullmatch(r"\w+", sid) else "signal", set(self.light_ctls))
        self.light_ctls[name] = {"signals": [sid], "el": el, "offset": 0.0, "phases": {}, "solo": True,
                                 "green": 0.0, "yellow": 0.0, "red": 0.0}
        self.signal_owner[sid] = name
        return name

    def light_clauses(self, action) -> list[ClausePlan]:
        """A GlobalAction's TrafficSignalAction as `light C state S` clauses ([] after a diagnostic)."""
        state_action = child_at(action, "InfrastructureAction", "TrafficSignalAction", "TrafficSignalStateAction")
        ctl_action = child_at(action, "InfrastructureAction", "TrafficSignalAction", "TrafficSignalControllerAction")
        if ctl_action is not None:
            raw = self.raw(ctl_action, "trafficSignalControllerRef")
            ref = self.ctl_names.get(raw, raw)
            if ref not in self.light_ctls or self.light_ctls[ref].get("solo"):
                self.error(ctl_action, f"no traffic signal controller '{raw}'",
                           f"controllers: {', '.join(c for c, v in self.light_ctls.items() if not v.get('solo'))}")
                return []
            self.approx(ctl_action, f"phase '{self.raw(ctl_action, 'phase')}': the controller resumes its program "
                                    "(`state program`), in its own cycle")
            return [ClausePlan(keyword="light", name=ref, settings={"state": LIGHT_PROGRAM})]
        if state_action is None:
            return []
        sid = self.raw(state_action, "name")
        ctl = self.light_controller(sid, state_action)
        state = self.signal_state(sid, self.raw(state_action, "state"), state_action) if ctl else None
        if state is None:
            return []
        return [ClausePlan(keyword="light", name=ctl, settings={"state": state})]

    def light_event(self, pairs: list) -> list[ClausePlan]:
        """The light clauses of one event's TrafficSignalActions ((action element, clause)
        pairs): one per controller; setting some of a controller's signals switches it all."""
        out, seen = [], {}
        for el, clause in pairs:
            seen.setdefault((clause.name, clause.settings["state"]), []).append(el)
        for (ctl, state), els in seen.items():
            info = self.light_ctls[ctl]
            if state != LIGHT_PROGRAM and len(els) < len(info["signals"]):
                self.approx(els[0], f"sets {len(els)} of the {len(info['signals'])} signals of controller '{ctl}': "
                                    "the language switches the whole controller")
            out.append(ClausePlan(keyword="light", name=ctl, settings={"state": state}))
        return out
