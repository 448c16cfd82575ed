"""Routing actions: trajectories to follow."""

from addt_dsl import expr as E
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.xml import first_of, only_child
from addt_dsl.plan import ClausePlan


class Routing:
    @ACTIONS.register("FollowTrajectoryAction", "approx", "polylines exactly; clothoids and NURBS sampled as "
                      "polylines (W0802); trajectories from catalogs refused")
    def act_trajectory(self, follow, who: str, act) -> ClausePlan | None:
        return self.trajectory(follow, who)

    def trajectory(self, follow, who: str) -> ClausePlan | None:
        traj = first_of(follow.find("TrajectoryRef/Trajectory"), follow.find("Trajectory"))
        if traj is None:
            self.skip(follow, "a trajectory from a catalog is not translated")
            return None
        shape = only_child(traj.find("Shape")) if traj.find("Shape") is not None else None
        if shape is None:
            self.error(first_of(traj.find("Shape"), traj), "a trajectory needs one shape")
            return None
        if shape.tag in ("Clothoid", "Nurbs"):
            got = self.clothoid(shape, who) if shape.tag == "Clothoid" else self.nurbs(shape, who)
            if got is None:
                return None
            points, times = got
            keys = ("x", "y")
            self.approx(shape, f"a {shape.tag.lower()} trajectory: sampled as a polyline of {len(points)} world "
                               "points (the language's trajectories are polylines)")
        elif shape.tag == "Polyline":
            points, times, keys = [], [], ("s", "t")
            for vertex in shape.iterfind("Vertex"):
                got = self.road_point(first_of(vertex.find("Position"), vertex), who)
                if got is None:
                    return None
                points.append(got)
                if vertex.get("time") is not None:
                    times.append(self.value(vertex, "time"))
            if len(points) < 1:
                self.error(shape, "a polyline needs vertices")
                return None
        else:
            self.skip(shape, f"<{shape.tag}> trajectories are not translated",
                      "polylines are; clothoids and NURBS are sampled")
            return None
        settings = {keys[0]: [E.Num(value=round(p[0], 9)) for p in points],
                    keys[1]: [E.Num(value=round(p[1], 9)) for p in points]}
        timing = follow.find("TimeReference/Timing")
        if timing is not None and times and len(times) == len(points):
            offset = self.value(timing, "offset", default=0.0)
            scale = self.value(timing, "scale", default=1.0)
            times = [scale * x + offset for x in times]
            if timing.get("domainAbsoluteRelative") == "absolute":
                self.approx(timing, "absolute vertex times: taken from the start of the trajectory")
            if all(b > a for a, b in zip(times, times[1:])) and times[0] >= 0.0:
                settings["times"] = [E.Num(value=round(x, 9)) for x in times]
            else:
                self.approx(timing, "vertex times that do not increase: driven at the default speed")
        clause = ClausePlan(keyword="behavior", name="trajectory", settings=settings)
        # Positions relative to an entity are placed from its initial place: exact for a
        # trajectory from the start; an event checks when it starts (`Storyboard.event`).
        for el in shape.iter():
            if el.tag.startswith("Relative") and el.get("entityRef"):
                self.relative_paths.append((clause, el, el.get("entityRef")))
                break
        return clause
