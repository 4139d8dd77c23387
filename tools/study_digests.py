"""Write tests/data/study_digests.json: the sha256 of every result file of reference studies.

Rule: the study's output is a contract. This script runs each study of
STUDIES (a reduced one the default suite re-runs in seconds, and the full
default study the slow suite and `pairplay bench` re-run) at seeds 0 and 3,
and records `report.study.output_digests` of each. Re-run it only when a
result is meant to change, and say which and why in the commit.

    python tools/study_digests.py [--only reduced|full]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from pairplay.report.study import StudySettings, output_digests, run_study

DIGESTS = Path(__file__).resolve().parents[1] / "tests" / "data" / "study_digests.json"
# name -> the StudySettings fields that differ from the defaults; each is run at every seed of SEEDS.
STUDIES = {
    "reduced": dict(games=2, rounds=60, eval_rounds=20, reuse_seeds=2, reuse_last=10),
    "full": {},
}
SEEDS = (0, 3)


def run(name: str, seed: int) -> dict[str, str]:
    with tempfile.TemporaryDirectory() as tmp:
        run_study(StudySettings(seed=seed, **STUDIES[name]), Path(tmp))
        return output_digests(Path(tmp))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=sorted(STUDIES))
    args = parser.parse_args()
    data = json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}
    for name in [args.only] if args.only else STUDIES:
        data[name] = {"settings": STUDIES[name], "seeds": {str(s): run(name, s) for s in SEEDS}}
    DIGESTS.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
