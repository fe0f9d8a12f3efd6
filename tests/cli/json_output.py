#!/usr/bin/env python3
"""The main program's --json output stays valid JSON for any input name.

usage: json_output.py LWSCCD_CCD WORK_DIR

Two frames under a folder whose name holds a double quote, a backslash and a tab; a step with
contacts (the upper triangle falls through the lower one). The output is parsed and its fields
checked: the input name kept as given, the contacts found, the counts of where pairs were decided.
"""
import json
import os
import shutil
import subprocess
import sys

PLY = """ply
format ascii 1.0
element vertex 6
property double x
property double y
property double z
element face 2
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
0.2 0.2 {z}
1.2 0.2 {z}
0.2 1.2 {z}
3 0 1 2
3 3 4 5
"""


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    program, work = sys.argv[1], sys.argv[2]
    shutil.rmtree(work, ignore_errors=True)
    folder = os.path.join(work, 'quote"and\\backslash\tand tab')
    os.makedirs(folder)
    frames = []
    for name, z in (("a.ply", 0.5), ("b.ply", -0.5)):
        frames.append(os.path.join(folder, name))
        with open(frames[-1], "w") as f:
            f.write(PLY.format(z=z))
    run = subprocess.run([program, frames[0], frames[1], "--json", "--device", "cpu"], capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"lwsccd-ccd failed ({run.returncode}): {run.stderr}")
    try:
        doc = json.loads(run.stdout)
    except json.JSONDecodeError as e:
        sys.exit(f"--json output is not valid JSON ({e}):\n{run.stdout}")
    assert frames[0] in doc["input"] and frames[1] in doc["input"], f"input name not kept: {doc['input']!r}"
    step = doc["steps"][0]
    hits = step["vf_hits"] + step["ee_hits"]
    assert hits > 0, f"the falling triangle's contacts were not found: {step}"
    assert 0.0 < step["earliest_toi"] < 1.0, step["earliest_toi"]
    decided = step["decided"]
    assert decided["fp32"] + decided["fp64"] + decided["fallback"] == step["vf_pairs"] + step["ee_pairs"], decided
    print(f"valid JSON; input {doc['input']!r}; {hits} contacts, earliest TOI {step['earliest_toi']}; decided {decided}")
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
