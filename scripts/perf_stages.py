#!/usr/bin/env python3
"""Where a run's CPU time goes, by stage: reads `perf script -F comm,tid,period,ip,sym` of a
`perf record --call-graph dwarf` run and gives each sample to the innermost frame of its stack that names a stage
(a fit's `Method::fit`, the judge, the d-optimal search, the arm in motion...). docs/speed.md has the commands."""
import collections
import re
import sys

# (stage, frame pattern), most specific first: a frame matching several stages gets the first.
STAGES = [
    ("fit: clock offset (trajectory campaigns)", r"calib::clock::estimate"),
    ("trajectory: the arm in motion + tracker", r"campaign::trajectory::measure|truth::motion"),
    ("fit: motion inputs", r"motion_inputs::with_motion_inputs"),
    ("d-optimal selection", r"DOptimal as .*Selector>::choose|design::select::"),
    ("space-filling thinning", r"SpaceFilling as .*Selector>::choose"),
    ("fit: hybrid, hybrid-kinematic (beyond their base fit)", r"residual::Hybrid as .*Method>::fit"),
    ("fit: residual-ridge", r"ResidualRidge as .*Method>::fit"),
    ("fit: paper-rotz/-rotxyz/-rotxyz-transxyz", r"paper::Paper as .*Method>::fit"),
    ("fit: kinematic/elastic (and hybrids' base)", r"kinematic::Kinematic as .*Method>::fit"),
    ("fit: other", r"as calibench::calib::method::Method>::fit"),
    ("judge: test split, grid, shell, closed loop", r"eval::judge::"),
    ("oracle floor", r"eval::oracle::"),
    ("observability indices", r"design::observability|DesignModel::jacobian"),
    ("ground truth build", r"eval::ground_truth::GroundTruth::build|campaign::ground_truth"),
    ("train/validation split", r"study::measure::split"),
    ("campaign generation (IK, collisions, sight, deflection, measuring)",
     r"campaign::generate|campaign::selected|campaign::sequence|Generator|campaign::points|study::measure::Measure"),
    ("report: plots", r"report::plots"),
    ("report: rerun recording", r"report::recording|report::trajectory_recording|re_log|re_chunk|re_types"),
    ("report: tables, csv, summary", r"calibench::report::"),
    ("the scenario's own campaign, budget, measurements.csv", r"app::campaign|measurements::|eval::budget|app::simulate"),
    ("writing files", r"output::write_dir"),
]
COMPILED = [(name, re.compile(p)) for name, p in STAGES]


def main(path):
    shares = collections.Counter()
    total = 0
    frames, period = [], 0

    def flush():
        nonlocal total
        if not frames:
            return
        total += period
        for frame in frames:
            for name, pattern in COMPILED:
                if pattern.search(frame):
                    shares[name] += period
                    return
        shares["unattributed"] += period

    for line in open(path, encoding="utf-8", errors="replace"):
        if not line.strip():
            flush()
            frames = []
        elif line[0] not in "\t ":
            parts = line.split()
            period = int(parts[2]) if len(parts) > 2 else 1
            frames = []
        else:
            parts = line.strip().split(None, 1)
            frames.append(parts[1] if len(parts) > 1 else "?")
    flush()
    for name, v in shares.most_common():
        print(f"{100 * v / total:6.2f} %  {name}")


if __name__ == "__main__":
    main(sys.argv[1])
