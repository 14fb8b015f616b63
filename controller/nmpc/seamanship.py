"""Seamanship in a narrow channel, as the COLREGs put it, turned into the NMPC's reference.

The vessel slots keep the boat clear of other vessels whatever the reference says; these
rules decide where the reference asks it to be, so that it passes the way other boats expect:

- Meeting (Rules 9 and 14): a vessel ahead coming the other way: keep to the starboard side
  of the channel, so the two pass port to port. The reference path moves to starboard by half
  of the room on that side, never closer than R_b + d_p to the starboard wall. Where the
  channel leaves the hull room beside the vessel all the way to it, its lane counts as taken
  from where the vessel will be to the end of the horizon (`Encounter.lane`,
  `vessel_slots`), so the plan moves over in time and keeps to its side instead of backing
  away from a vessel it can pass.
- Overtaking (Rules 9(e) and 13): a slower vessel ahead going the same way: pass it on its port
  side where the channel there leaves room for the boat and for a vessel coming the other
  way too (2 R_b + 2 d_v + `oncoming_room_m`), else on its starboard side where that leaves
  the boat room (2 R_b + d_v + d_p: out of the lane of anyone coming the other way), else on
  its port side only if the channel is seen clear far enough (`sight_m`) that nothing unseen
  coming the other way at `oncoming_mps` can be there before the boat is past; never on the
  side a vessel given way to is crossing to (Rule 15: the boat passes astern of it). With no
  such side, or a bend of more than `bend_deg` before the boat would be past it (Rule 9(f):
  what comes round the bend is not seen), follow it: no faster than it goes, and stop short
  of it by `follow_gap_m` (its stern to our bow). The farthest vessel is decided first: one
  close behind another (no room to pull in between) is passed on that one's side or followed
  with it, and no pass beyond a vessel followed moves the reference. A side chosen is kept
  while its room stays within `keep_side_m` (Rule 8: a track's noise does not switch the boat
  between sides, or between passing and following); a pass on the vessel's starboard side
  goes on while a vessel is met (it is out of that vessel's lane), one on its port side stops.
  Beside a vessel the boat never changes sides (that is across its bow): with no room left on
  its side it falls back and follows.
- Crossing (Rule 15): a vessel that will cross the route ahead from the starboard side while
  the boat would be there is given way to by slowing: the reference stops short of the
  crossing point until the vessel has cleared it (passing astern of it), by R_b + d_v from
  half its length, not its beam: out of a side canal a vessel turns into the channel, and
  its hull then reaches half its length either way from where it crossed. A small craft
  (shorter than `small_craft_m`: a kayak, a rowing boat) is given way to from either side,
  and a vessel once given way to stays so until it has crossed (Rule 8: a track first seen
  short grows as its hull comes out from behind a corner; the boat does not then change its
  mind and speed up into it).
- Stand on (Rule 17): a vessel crossing from port keeps out of our way: course and speed stay
  as planned (the vessel slot still keeps the boat clear if it does not), until the crossing
  point is no farther than the boat needs to stop with its hardest braking (`act_decel_mps2`,
  and its bow): then the give-way vessel has not acted, and the boat stops short of the
  crossing point as when giving way (Rule 17(b)), which is no turn to port (Rule 17(c)); as
  with giving way, the decision stands until the vessel has crossed.

Everything is worked out in the route's frame (arc length s along the waypoint path, offset d
across it, + to starboard) from the tracks' positions and velocities. Why the reference and
not the cost: the cost still weighs the plan against the reference exactly as in the paper,
the constraints stay the safety net, and each rule is one line of geometry a reader can check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .reference import WaypointPath
from .slack_reference import walls_abeam


@dataclass(frozen=True)
class Encounter:
    """How one vessel stands to the boat, and what the rules ask for."""

    track_id: object
    kind: str  # meeting | overtaking | following | give_way | stand_on | stand_on_acts |
    # astern | clear
    distance_m: float  # along the route, its centre from the boat (< 0: behind)
    # meeting: the channel leaves the hull room to pass it on its port side all the way to
    # it (d_v beside it, R_b to the wall: `lane_room`), so its lane counts as taken for the
    # whole horizon (`vessel_slots`); without room the boat holds back from its hull
    lane: bool = False
    side: str = ""  # overtaking: the vessel's side the boat passes it on (port | starboard)


@dataclass(frozen=True)
class Shaping:
    """What the rules ask of the reference this period."""

    offset_m: float = 0.0  # move the reference path across (+ to starboard)
    speed_mps: float | None = None  # a speed cap (follow a slower vessel)
    stop_at_m: float | None = None  # stop here (arc length along the path), until it clears
    reason: str = ""  # "meeting 3: keep to starboard", for the log
    encounters: tuple = ()


def assess(tracks, path: WaypointPath, progress_m: float, offset_m: float, speed_mps: float,
           segments, *, hull_radius_m: float, separation_m: float, vessel_separation_m: float,
           bow_m: float, follow_gap_m: float = 20.0, lookahead_m: float = 70.0,
           small_craft_m: float = 6.0, bend_deg: float = 20.0,
           give_way_to: frozenset = frozenset(), act_decel_mps2: float = 0.15,
           sight_m: float = math.inf, oncoming_mps: float = 2.5,
           oncoming_room_m: float = 5.0, overtaking: dict | None = None,
           keep_side_m: float = 1.0) -> Shaping:
    """The reference shaping for the tracked vessels (`perception.tracking.Track`-like:
    position, velocity, length_m, width_m, id); segments give the channel's walls;
    `give_way_to`: ids the boat gave way to (or stood on for and then acted) at the last
    period; `act_decel_mps2`: the boat's hardest braking, which sets how late a stand-on
    vessel may keep its course and speed (Rule 17(b)); `sight_m`: how far ahead a vessel is
    seen (the perception's reach), `oncoming_mps` and `oncoming_room_m`: the speed and the
    room across (beam and its way off the wall) of a vessel coming the other way unseen;
    `overtaking`: {track id: side} the boat was overtaking on at the last period, a side kept
    while its room stays within `keep_side_m` of what choosing it asks (Rule 8: a track's
    noise does not switch the boat from side to side or between passing and following)."""
    if not tracks:
        return Shaping()
    segs = np.asarray(segments, float).reshape(-1, 4)
    Rb, dp, dv = hull_radius_m, separation_m, vessel_separation_m
    speed_cap, stop, reasons, encounters = None, None, [], []
    meet_offset, pass_offsets = 0.0, []
    room_here = []  # the walls abeam of the boat's place on the path, when first needed

    def here() -> tuple[float, float]:
        if not room_here:
            xy0, heading0 = path.at(progress_m)
            room_here.append(_beside(xy0, heading0, 0.0, 0.0, segs))
        return room_here[0]

    overtakes = []  # (track, s, d, half_len, half_wid, along, port_gap, stbd_gap)
    heading_to = set()  # the sides (+1 starboard, -1 port) vessels given way to cross to
    tracks = list(tracks)
    positions = np.array([np.asarray(tr.position, float).reshape(2) for tr in tracks])
    # every vessel on the path at once (the same answer as one at a time)
    s_all, d_all = path.frame(positions, max(progress_m - 40.0, 0.0), progress_m + lookahead_m)
    _, headings = path.at(s_all)
    for k, (tr, s, d, h) in enumerate(zip(tracks, s_all.tolist(), d_all.tolist(),
                                          headings.tolist())):
        v = np.asarray(tr.velocity, float).reshape(2)
        heading = headings[k:k + 1]
        along = float(v[0] * math.cos(h) + v[1] * math.sin(h))
        across = float(-v[0] * math.sin(h) + v[1] * math.cos(h))  # + to starboard
        ahead = s - progress_m
        half_len, half_wid = 0.5 * float(tr.length_m), 0.5 * float(tr.width_m)
        kind = "clear"
        if ahead + half_len < -bow_m or ahead > lookahead_m:
            kind = "astern" if ahead < 0 else "clear"
        elif abs(d) > half_wid + Rb + dv + 8.0 and abs(across) < 0.2:
            kind = "clear"  # well aside and not closing: moored, or on another channel
        elif _crossing(d, along, across, half_wid):
            crossing = _conflict(ahead, d, along, across, half_len, half_wid, speed_mps,
                                 Rb + dv + bow_m)
            if crossing is not None:
                small = float(tr.length_m) < small_craft_m
                from_starboard = across < 0  # it moves to port: it comes from starboard
                # give way (to a small craft from either side); a decision to give way
                # stands while the conflict lasts (Rule 8: no back and forth), though the
                # track grows out of small craft as more of its hull comes into view
                # short of where it crosses by its half length: a vessel that turns into
                # the channel there swings its stern (or bow) that far toward the boat
                # (seed 1 case 3: stopped short of its beam, 1.6 m from its turning stern)
                at = progress_m + crossing - (Rb + dv + bow_m + max(half_wid, half_len))
                # Rule 17(b): still on a collision course when the boat could only just
                # stop short with its hardest braking, the give-way vessel has not acted:
                # the boat stops short of the crossing point as when giving way (never a
                # turn to port for a vessel on its port side, Rule 17(c))
                late = at - progress_m <= speed_mps * speed_mps / (2.0 * act_decel_mps2) + bow_m
                if from_starboard or small:
                    kind = "give_way"
                    reasons.append(f"give way to {tr.id} crossing from "
                                   f"{'starboard' if from_starboard else 'port'}")
                elif late or tr.id in give_way_to:
                    kind = "stand_on_acts"
                    reasons.append(f"stand-on acts: {tr.id} crossing from port has not "
                                   f"given way")
                else:
                    kind = "stand_on"
                if kind != "stand_on":
                    stop = at if stop is None else min(stop, at)
                    heading_to.add(1.0 if across > 0 else -1.0)
        elif abs(along) < 0.5 or abs(along) < abs(across):
            kind = "clear"  # drifting, or moving away across the route: the slot keeps clear
        elif along < 0 and ahead > 0:
            kind = "meeting"
            stbd0 = here()[1]
            room = stbd0 - (Rb + dp)  # how far to starboard the boat may go
            move = max(min(0.5 * stbd0, room), 0.0) if math.isfinite(stbd0) else Rb + dp
            meet_offset = max(meet_offset, move)
            reasons.append(f"meeting {tr.id}: keep to starboard")
            lane = lane_room(path, progress_m, s, d + half_wid, segs) >= dv + 2 * Rb
            encounters.append(Encounter(tr.id, kind, ahead, lane))
            continue
        elif ahead > 0 and along < speed_mps - 0.3:
            kind = "overtaking"  # or following, decided below
            # the channel beside the vessel, measured from just outside its sides (the
            # LiDAR's lines on its own hull are no wall beside it)
            xy_v, _ = path.at(s)
            edge = 0.5
            port_gap, stbd_gap = _beside(xy_v, heading, d - half_wid - edge,
                                         d + half_wid + edge, segs)
            port_gap = edge + port_gap if math.isfinite(port_gap) else (
                (d - half_wid) + here()[0])  # not seen there yet: as here
            stbd_gap = edge + stbd_gap if math.isfinite(stbd_gap) else (
                here()[1] - (d + half_wid))
            overtakes.append((tr, s, d, half_len, half_wid, along, port_gap, stbd_gap,
                              len(encounters)))
        encounters.append(Encounter(tr.id, kind, ahead))
    # Overtake only with room beside the vessel, nobody coming the other way in the lane the
    # boat takes, and the channel straight until the boat is past (Rule 9(f): round a bend a
    # vessel coming the other way is out of sight until it is there). The farthest vessel
    # is decided first: one close behind another (no room to pull in between them) is
    # passed on the same side as that one, or followed with it.
    need = 2 * Rb + dv + dp
    three_abreast = 2 * Rb + 2 * dv + oncoming_room_m  # the boat and one coming the other way
    room_between = 2.0 * (bow_m + follow_gap_m)  # to pull in between two vessels
    ahead_of = None  # (its stern's arc length, the side it is passed on or None) so far
    for tr, s, d, half_len, half_wid, along, port_gap, stbd_gap, k in sorted(
            overtakes, key=lambda o: -o[1]):
        side, why = None, "no room to overtake"
        past = (s - progress_m) + half_len + bow_m + follow_gap_m  # to be clear ahead of it
        duration = past / max(speed_mps - along, 0.1)
        travel = speed_mps * duration  # the boat's way meanwhile
        # nothing coming the other way can reach the boat's way before it is past: the
        # channel is seen clear beyond where it will be by what such a vessel makes meanwhile
        seen_clear = travel + oncoming_mps * duration <= sight_m
        alongside = (s - progress_m) - half_len < bow_m  # its stern behind our bow: go on
        before = (overtaking or {}).get(tr.id)
        # on its port side the boat is in the lane of whatever comes the other way: only
        # where there is room for that vessel too, or none can come unseen (or the boat is
        # beside it already, where going on is the shorter way out of that lane); a side
        # chosen is kept while its room stays within keep_side_m of what choosing it asks;
        # never to the side a vessel given way to is crossing to (Rule 15: pass astern of it)
        give = keep_side_m if before == "port" else 0.0
        port_ok = (port_gap >= need - give and -1.0 not in heading_to
                   and (port_gap >= three_abreast - give or seen_clear or alongside))
        # on its starboard side the boat keeps out of that lane
        stbd_ok = (stbd_gap >= need - (keep_side_m if before == "starboard" else 0.0)
                   and 1.0 not in heading_to)
        chained = ahead_of is not None and ahead_of[0] - (s + half_len) < room_between
        if not alongside and not _straight(path, progress_m,
                                           progress_m + min(travel, 2 * lookahead_m),
                                           math.radians(bend_deg)):
            why = "a bend ahead before the boat would be past"
        elif chained and ahead_of[1] is None and not alongside:
            why = "a vessel close ahead of it is followed"
        elif meet_offset != 0.0 and not (stbd_ok and (before == "starboard" or offset_m > d)):
            why = "no room to overtake with a vessel coming the other way"
        elif meet_offset != 0.0:
            side = "starboard"  # on its starboard side, out of the lane of the vessel met
        elif chained:  # the vessel close ahead's side, if this one leaves room on it
            side = ahead_of[1] if (port_ok if ahead_of[1] == "port" else stbd_ok) else None
        elif alongside and not (stbd_ok if offset_m > d else port_ok):
            # beside it, the other side is reached only across its bow: the boat falls back
            # (seed 1 case 109, varied: a kayak stopped ahead on the starboard side turned a
            # starboard pass into a port one, and the boat cut across a barge's bow into it)
            why = "no room on the side the boat is beside it"
        elif alongside and offset_m > d and stbd_ok:
            side = "starboard"  # beside it already: on the side the boat is on
        elif port_ok and (port_gap >= three_abreast or alongside or before == "port"):
            side = "port"
        elif stbd_ok:
            side = "starboard"
        elif port_ok:
            side = "port"
        if side is None and why == "no room to overtake":
            why += (" clear of a vessel crossing" if heading_to else
                    " with the way ahead seen too short" if port_gap >= need else "")
        ahead_of = (s - half_len, side)
        if side is not None:  # beside it, and R_b + d_p off the wall (from the path: port,
            # stbd), whichever is nearer the path
            port, stbd = port_gap - (d - half_wid), stbd_gap + (d + half_wid)
            target = (max(d - half_wid - dv - Rb, -(port - Rb - dp)) if side == "port" else
                      min(d + half_wid + dv + Rb, stbd - Rb - dp))
            pass_offsets.append((s - progress_m, target))
            reasons.append(f"overtaking {tr.id} on its {side} side")
            encounters[k] = Encounter(tr.id, "overtaking", encounters[k].distance_m, side=side)
            continue
        encounters[k] = Encounter(tr.id, "following", encounters[k].distance_m)
        speed_cap = along if speed_cap is None else min(speed_cap, along)
        at = s - half_len - bow_m - follow_gap_m
        stop = at if stop is None else min(stop, at)
        reasons.append(f"following {tr.id}: {why}")
    # the nearest vessel overtaken sets the side (passed on its starboard side while meeting
    # one: out to starboard at least as far as the meeting asks); none beyond one followed
    followed = [e.distance_m for e in encounters if e.kind == "following"]
    pass_offsets = [p for p in pass_offsets if not followed or p[0] < min(followed)]
    offset = min(pass_offsets)[1] if pass_offsets else 0.0
    offset = max(meet_offset, offset) if meet_offset else offset
    if speed_cap is not None:
        speed_cap = max(speed_cap, 0.0)
    return Shaping(offset, speed_cap, stop, "; ".join(reasons), tuple(encounters))


def _straight(path: WaypointPath, s0: float, s1: float, max_turn_rad: float) -> bool:
    """The route turns by no more than `max_turn_rad` between arc lengths s0 and s1 (its
    headings are unwrapped along it)."""
    _, heading = path.at(np.linspace(s0, max(s0, s1), 9))
    return float(np.max(np.abs(heading - heading[0]))) <= max_turn_rad


def lane_room(path: WaypointPath, s_boat: float, s_vessel: float, edge_m: float, segs,
              samples: int = 6) -> float:
    """The least room (m) to starboard of a vessel met head-on, from its starboard edge
    (`edge_m` across the route, + to starboard) to the starboard wall, at `samples` places
    from the boat to the vessel: where the two may pass (inf: no wall seen)."""
    s = np.linspace(s_boat, s_vessel, samples)
    xy, heading = path.at(s)
    _, stbd = walls_abeam(xy, heading, segs)
    return float(np.min(stbd - edge_m))


def _beside(xy, heading, port_edge_m, stbd_edge_m, segs) -> tuple[float, float]:
    """Distance to the wall abeam to port of the path point moved `port_edge_m` across (+ to
    starboard), and to starboard of it moved `stbd_edge_m` across (inf: none seen); both 0:
    the channel abeam of the path point itself."""
    pts = np.asarray(xy, float).reshape(1, 2)
    h = float(np.asarray(heading, float).reshape(-1)[0])
    normal = np.array([-math.sin(h), math.cos(h)])
    port, stbd = walls_abeam(pts + np.outer((port_edge_m, stbd_edge_m), normal),
                             np.array([h, h]), segs)
    return float(port[0]), float(stbd[1])


def _crossing(d: float, along: float, across: float, half_wid: float) -> bool:
    """The vessel is aside of the route and moving toward it (or across it), on a course
    more than about 27 degrees off the route's: a vessel met or overtaken in the channel
    drifts across it too, and a track's velocity has noise, but that is no crossing."""
    return (abs(across) > max(0.2, 0.5 * abs(along))
            and (d * across < 0 or abs(d) <= half_wid))


def _conflict(ahead, d, along, across, half_len, half_wid, speed, reach):
    """Where along the route (m ahead of the boat) the vessel crosses it, if the boat would
    be there while the vessel is within `reach` of the route; else None."""
    t_in = (abs(d) - half_len - reach) / abs(across)  # its hull reaches the route's zone
    t_out = (abs(d) + half_len + reach) / abs(across)  # and has cleared it
    t_in, t_out = max(t_in, 0.0), max(t_out, 0.0)
    if t_out <= 0.0:
        return None
    at = ahead + along * 0.5 * (t_in + t_out)  # where on the route it crosses
    if at < -reach:
        return None  # it crosses behind the boat
    if speed <= 0.05:
        return at  # stopped: stay stopped while it crosses
    t_boat_in = (at - reach) / speed
    t_boat_out = (at + reach) / speed
    return at if t_boat_in <= t_out and t_boat_out >= t_in else None
