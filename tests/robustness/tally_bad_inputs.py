"""Tally the bad-input log of the robustness tests into the table of ``README.md``.

    rm -f /tmp/bad.jsonl
    BLURTRAP_BAD_INPUT_LOG=/tmp/bad.jsonl python -m pytest -n 2 tests/robustness
    python tests/robustness/tally_bad_inputs.py /tmp/bad.jsonl

A line is logged only after ``pytest.raises(..., match=...)`` accepted the error (type and
message naming the file / parameter / value), so every logged input got a clear error; a bad
input without one fails its test instead of being counted. Category prefixes group the rows.
"""

import collections
import json
import sys


def tally(path):
    tried = collections.Counter()
    distinct = collections.defaultdict(set)
    with open(path, encoding="utf-8") as f:
        for line in f:
            d = json.loads(line)
            tried[d["category"]] += 1
            distinct[d["category"]].add(d["input"])
    return tried, distinct


def main(path):
    tried, distinct = tally(path)
    rows = ["| category | bad inputs tried | distinct inputs | with a clear error |",
            "|---|---:|---:|---:|"]
    groups = collections.defaultdict(list)
    for cat in tried:
        groups[cat.split(":")[0]].append(cat)
    total = 0
    for group in sorted(groups):
        for cat in sorted(groups[group]):
            rows.append(f"| {cat} | {tried[cat]} | {len(distinct[cat])} | {tried[cat]} |")
            total += tried[cat]
    rows.append(f"| **total** | **{total}** | **{sum(len(v) for v in distinct.values())}** | "
                f"**{total}** |")
    print("\n".join(rows))


if __name__ == "__main__":
    main(sys.argv[1])
