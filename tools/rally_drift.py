#!/usr/bin/env python3
"""Where the robot that served is when the ball comes back: a replay's between-strokes drift.

Reads a replay written by `rally match A B --replay FILE` (MyoSuite's robot: `--model myochallenge`)
and, for every rally whose first return bounced on the server's half of the table, reports how
close the server's paddle got to the ball on that side, and where the server's pelvis slides
(`qpos[0]` = pelvis_x, `qpos[1]` = pelvis_y) were at that moment. A robot that stands ready meets
the ball (closest approach of a few centimetres); one that wandered off while the ball was away
misses it by far. The server is the side the ball starts on (the rally serve leaves from the
server's hitting plane); a return is the first reversal of the ball's direction along the table.

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

# Half the table's length along x (m): the arena's table is 2.74 m long, centred on x = 0.
TABLE_HALF_LENGTH = 1.37


def server_drift(frames):
    """(closest approach in m, pelvis x, pelvis y) of the server, or None when no ball came back."""
    xs = [f["ball"][0] for f in frames]
    side = "a" if xs[0] > 0 else "b"
    sign = 1.0 if side == "a" else -1.0
    # The first reversal of the ball's motion along x: the receiver's touch.
    turn = next(
        (i for i in range(1, len(xs) - 1) if (xs[i] - xs[i - 1]) * (xs[i + 1] - xs[i]) < 0),
        None,
    )
    if turn is None:
        return None
    back = [f for f in frames[turn:] if sign * f["ball"][0] > 0]
    # Only a return that bounced on the server's half (the ball's fall turned into a rise over the
    # table): a ball the server had to play.
    zs = [f["ball"][2] for f in back]
    bounced = any(
        zs[i] < zs[i - 1] and zs[i] <= zs[i + 1] and abs(back[i]["ball"][0]) < TABLE_HALF_LENGTH
        for i in range(1, len(zs) - 1)
    )
    if not bounced:
        return None
    best = min(back, key=lambda f: math.dist(f["ball"], f["paddle_" + side][:3]))
    q = best["qpos_" + side]
    return math.dist(best["ball"], best["paddle_" + side][:3]), q[0], q[1]


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
