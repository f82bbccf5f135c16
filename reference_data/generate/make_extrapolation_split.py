"""Candidate / evaluation split of the held-out half of each bundled room (SPEC.md §20.7).

The pipeline is given the *candidate* poses (with the ground-truth generator: their truth);
the *evaluation* poses are never given to anything and score the result. Rule: held-out
views in name order, every third one (index % 3 == 0) is a candidate, the others are
evaluation poses. Both files are INRIA cameras.json subsets of the scene's cameras.json,
copied entry for entry. No third-party package needed: python make_extrapolation_split.py
"""
import json
import os

ROOT = os.path.join(os.path.dirname(__file__), "..", "scenes")

for scene in ("lounge", "gallery"):
    d = os.path.join(ROOT, scene)
    cams = json.load(open(os.path.join(d, "cameras.json")))
    by_name = {c["img_name"]: c for c in cams}
    held = sorted(json.load(open(os.path.join(d, "split.json")))["heldout"])
    cand = [by_name[n] for k, n in enumerate(held) if k % 3 == 0]
    evals = [by_name[n] for k, n in enumerate(held) if k % 3 != 0]
    for name, lst in (("candidates.json", cand), ("evaluation.json", evals)):
        with open(os.path.join(d, name), "w") as f:
            json.dump(lst, f, indent=1)
            f.write("\n")
    print(scene, len(cand), "candidates,", len(evals), "evaluation poses")
