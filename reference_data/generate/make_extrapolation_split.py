"""Candidate / evaluation split of each bundled room for `unseen extrapolate` (SPEC.md §20.7).

The pipeline is given the *candidate* poses (with the ground-truth generator: their truth);
the *evaluation* poses are never given to anything and score the result. Candidates are
the even-numbered `bridge` views (made by make_bridge_views.py: each sees 15-60 % of
surface the train half saw, the rest unseen); evaluation poses are the odd-numbered
bridge views (the held-out half proper lies mostly beyond what these candidates see).
Both files are INRIA cameras.json subsets of the scene's cameras.json, copied entry for
entry. No third-party package needed:
python make_extrapolation_split.py
"""
import json
import os

ROOT = os.path.join(os.path.dirname(__file__), "..", "scenes")

for scene in ("lounge", "gallery"):
    d = os.path.join(ROOT, scene)
    cams = json.load(open(os.path.join(d, "cameras.json")))
    by_name = {c["img_name"]: c for c in cams}
    split = json.load(open(os.path.join(d, "split.json")))
    bridge = sorted(split["bridge"])
    cand = [by_name[n] for k, n in enumerate(bridge) if k % 2 == 0]
    evals = [by_name[n] for k, n in enumerate(bridge) if k % 2 == 1]
    for name, lst in (("candidates.json", cand), ("evaluation.json", evals)):
        with open(os.path.join(d, name), "w") as f:
            json.dump(lst, f, indent=1)
            f.write("\n")
    print(scene, len(cand), "candidates,", len(evals), "evaluation poses")
