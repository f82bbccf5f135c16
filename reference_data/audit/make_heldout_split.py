#!/usr/bin/env python3
"""A room with another split of its held-out half (issue #72's first reading): the candidate
poses are every other held-out camera (even positions), the evaluation poses the rest (odd),
where the bundled rooms generate at bridge views between the halves and evaluate elsewhere.

Usage: reference_data/audit/make_heldout_split.py ROOM_DIR OUT_DIR
  Writes OUT_DIR with links to ROOM_DIR's files and its own candidates.json and
  evaluation.json (INRIA cameras.json entries of ROOM_DIR's cameras.json, named in
  split.json's "heldout" list). Standard library only. Then, e.g.:
  GENERATORS=truth-none,classical VARIANTS=full,originals_only \
    reference_data/audit/run_training_half.sh OUT_DIR 0..2
"""
import json
import os
import sys


def main(room: str, out: str) -> None:
    room = os.path.abspath(room)
    split_path = os.path.join(room, "split.json")
    cams_path = os.path.join(room, "cameras.json")
    for p in (split_path, cams_path):
        if not os.path.isfile(p):
            sys.exit(f"{p}: missing (a room with split.json and cameras.json is needed)")
    held = json.load(open(split_path)).get("heldout")
    if not held:
        sys.exit(f"{split_path}: no 'heldout' list")
    cams = {c["img_name"]: c for c in json.load(open(cams_path))}
    missing = [n for n in held if n not in cams]
    if missing:
        sys.exit(f"{cams_path}: no camera named {missing[0]} (split.json's heldout)")
    os.makedirs(out, exist_ok=True)
    for name in sorted(os.listdir(room)):
        if name in ("candidates.json", "evaluation.json"):
            continue
        link = os.path.join(out, name)
        if not os.path.lexists(link):
            os.symlink(os.path.join(room, name), link)
    for name, picked in (("candidates.json", held[0::2]), ("evaluation.json", held[1::2])):
        with open(os.path.join(out, name), "w") as f:
            json.dump([cams[n] for n in picked], f, indent=1)
    print(f"{out}: {len(held[0::2])} candidate and {len(held[1::2])} evaluation poses")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
