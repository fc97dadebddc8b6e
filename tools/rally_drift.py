#!/usr/bin/env python3
"""Where the robot that served is when the ball comes back: a replay's between-strokes drift.

Reads a replay written by `rally match A B --replay FILE` (MyoSuite's robot: `--model myochallenge`)
and, for every rally whose first return bounced on the server's half of the table, reports how
close the server's paddle got to the ball on that side, and where the server's pelvis slides
(`qpos[0]` = pelvis_x, `qpos[1]` = pelvis_y) were at that moment. A robot that stands ready meets
the ball (a closest approach of about the blade's size, ~0.1 m); one that wandered off while the
ball was away misses it by far. The server is the side the ball starts on (the rally serve leaves from the
server's hitting plane); the receiver's touch is taken as the first reversal of the ball's motion
along the table on the receiver's half. Distances are from the ball's centre to the paddle's, both
taken as moving linearly between the replay's 50 Hz frames.

Usage: tools/rally_drift.py REPLAY.json [--near 0.15]
e.g.   target/release/rally match CKPT CKPT --model myochallenge --rallies 40 --seed 4242 --replay r.json
       tools/rally_drift.py r.json
Standard library only.
"""
import argparse
import json
import math
import statistics
import sys

# The arena's table (m): x in [-1.37, 1.37], y in 0.04 +- 0.76, its top at z = 0.795 (sim/src/arena.rs).
TABLE_HALF_LENGTH = 1.37
TABLE_CENTER_Y = 0.04
TABLE_HALF_WIDTH = 0.76
TABLE_TOP = 0.795
# Slack on a bounce's sampled position: at 50 Hz a ball moves ~0.1 m between frames.
SLACK = 0.12


def closest(f0, f1, side):
    """Least ball-to-paddle-centre distance between two frames, both moving linearly in between."""
    p0 = [b - p for b, p in zip(f0["ball"], f0["paddle_" + side][:3])]
    p1 = [b - p for b, p in zip(f1["ball"], f1["paddle_" + side][:3])]
    d = [b - a for a, b in zip(p0, p1)]
    dd = sum(x * x for x in d)
    s = 0.0 if dd == 0.0 else min(1.0, max(0.0, -sum(a * b for a, b in zip(p0, d)) / dd))
    return math.sqrt(sum((a + s * b) ** 2 for a, b in zip(p0, d)))


def server_drift(frames):
    """(closest approach in m, pelvis x, pelvis y) of the server, or None when no return bounced
    on its half."""
    xs = [f["ball"][0] for f in frames]
    side = "a" if xs[0] > 0 else "b"
    sign = 1.0 if side == "a" else -1.0
    # The receiver's touch, taken as the first reversal of the ball's motion along x on the
    # receiver's half.
    turn = next(
        (
            i
            for i in range(1, len(xs) - 1)
            if (xs[i] - xs[i - 1]) * (xs[i + 1] - xs[i]) < 0 and sign * xs[i] < 0
        ),
        None,
    )
    if turn is None:
        return None
    # The return's flight on the server's side: from its crossing of x = 0 until it next turns
    # back or the rally ends.
    back = []
    for i in range(turn + 1, len(frames)):
        if sign * xs[i] > 0:
            back.append(frames[i])
            if i + 1 < len(xs) and (xs[i + 1] - xs[i]) * sign < 0:
                break
        elif back:
            break
    # Only a return that bounced on the server's half of the table (the ball's fall turned into a
    # rise low over the table; the rally's last frame is not one): a ball the server had to play.
    bounced = any(
        back[i]["ball"][2] < back[i - 1]["ball"][2]
        and back[i]["ball"][2] <= back[i + 1]["ball"][2]
        and back[i]["ball"][2] < TABLE_TOP + 0.25
        and abs(back[i]["ball"][0]) < TABLE_HALF_LENGTH + SLACK
        and abs(back[i]["ball"][1] - TABLE_CENTER_Y) < TABLE_HALF_WIDTH + SLACK
        for i in range(1, len(back) - 1)
    )
    if not bounced:
        return None
    pairs = list(zip(back, back[1:])) or [(back[0], back[0])]
    d, f0 = min(((closest(a, b, side), a) for a, b in pairs), key=lambda t: t[0])
    q = f0["qpos_" + side]
    return d, q[0], q[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("replay", help="a replay JSON file from `rally match --replay`")
    ap.add_argument("--near", type=float, default=0.15, help="a closest approach under this counts as met (m)")
    args = ap.parse_args()
    try:
        with open(args.replay) as f:
            replay = json.load(f)
        rallies = replay["rallies"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        sys.exit(f"error: {args.replay}: not a replay from `rally match --replay` ({e})")
    rows = [r for r in (server_drift(fr) for fr in rallies if len(fr) > 2) if r is not None]
    print(f"{len(rallies)} rallies, {len(rows)} with a return bouncing on the server's half")
    if not rows:
        return
    d = [r[0] for r in rows]
    print(f"closest approach: mean {statistics.fmean(d):.2f} m, median {statistics.median(d):.2f} m, "
          f"under {args.near} m in {sum(x < args.near for x in d)} of {len(d)}")
    print(f"server's pelvis then: x mean {statistics.fmean(r[1] for r in rows):.2f} m, "
          f"|y| mean {statistics.fmean(abs(r[2]) for r in rows):.2f} m")


if __name__ == "__main__":
    main()
