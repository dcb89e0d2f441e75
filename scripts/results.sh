#!/usr/bin/env bash
# The current walking figures, regenerated: builds the firmware for the emulated board (QEMU
# mps2-an500, Cortex-M7) and the host tools as scripts/walk.sh does, walks the firmware in the
# loop on the MuJoCo robot (seed 0) and writes docs/results.md and the README's figures table
# (between `<!-- results:begin -->` and `<!-- results:end -->`).
#
# The walks (each a `walker` command whose report the tables are taken from):
#   out/results/default/       walker sweep --plan plans/table2.toml
#                              (the firmware's defaults at their stretched timing; nominal row
#                              = the README's first row, the whole table = the robustness sweep)
#   out/results/paper-timing/  walker sweep --plan plans/table2.toml --firmware-args feasibility=off
#   out/results/paper-open/    walker sweep --plan plans/table2-paper.toml (the paper's open loop)
#   out/results/servos/        walker sweep --family servos --plan plans/table2.toml --ablate
#                              (defaults/: the defaults across the servo family; FEATURE/: the
#                              same with one feature off; ablation.md: which earns its place)
#   out/results/servos-open/   walker sweep --family servos --plan plans/table2-paper.toml
#   out/results/ablation/      walker beyond --ablation --plan plans/table2.toml
#   out/results/pushes/        walker pushes --plan plans/table2.toml
#   out/results/op3/           walker sweep --family servos --plan plans/op3-forward.toml
#                              (the ROBOTIS OP3: its plan, the defaults across the servo family)
# Each sweep row is scored as `walker sweep` does: distance, heading drift and tilt from the
# truth (host/src/fil.rs `walk_figures`), true CoP − reference mean |e| over the walking ticks
# (host/src/beyond.rs `score`).
#
# Options: SKIP_WALKS=1 only rewrites the docs from the reports already in out/results/;
# RESULTS_OUT=DIR puts the reports elsewhere. ≈ 50 walks: tens of minutes on 2 cores.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
out=${RESULTS_OUT:-out/results}

if [ "${SKIP_WALKS:-0}" != 1 ]; then
    source scripts/setup.sh
    echo "== building the firmware (board-qemu) and the host tools"
    cargo build --release --no-default-features --features board-qemu --bin qemu
    cargo build --release --target host-tuple -p walker-host --bin walker
    walker=target/$(rustc -vV | sed -n 's/^host: //p')/release/walker

    # A run that falls makes `walker sweep` / `beyond` / `pushes` exit non-zero after writing
    # its report; the report is what counts here.
    walk() {
        local dir=$1
        shift
        echo
        echo "== $dir: walker $*"
        # Fresh: `walker sweep --ablate` resumes from the rows an earlier run left there.
        rm -rf "${out:?}/$dir"
        "$walker" "$@" --out "$out/$dir" || echo "   (walker exited with $?; its report is kept)"
    }
    jobs=$(nproc 2>/dev/null || echo 1)
    walk default sweep --plan plans/table2.toml --jobs "$jobs"
    walk paper-timing sweep --plan plans/table2.toml --firmware-args "feasibility=off" --jobs "$jobs"
    walk paper-open sweep --plan plans/table2-paper.toml --jobs "$jobs"
    walk servos sweep --family servos --plan plans/table2.toml --ablate --jobs "$jobs"
    walk servos-open sweep --family servos --plan plans/table2-paper.toml --jobs "$jobs"
    walk ablation beyond --ablation --plan plans/table2.toml
    walk pushes pushes --plan plans/table2.toml
    walk op3 sweep --family servos --plan plans/op3-forward.toml --jobs "$jobs"
fi

echo
echo "== writing docs/results.md and the README's figures table"
python3 - "$out" <<'EOF'
import os, re, subprocess, sys

out = sys.argv[1]

def read(path):
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except FileNotFoundError:
        return None

def table(md):
    """The first Markdown table of `md` (its lines), or []."""
    if md is None:
        return []
    lines, started = [], False
    for line in md.splitlines():
        if line.startswith("|"):
            lines.append(line)
            started = True
        elif started:
            break
    return lines

def cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]

def nominal(name):
    """README row of a sweep's nominal case: fall, distance (m, %), heading, true x / y."""
    for line in table(read(f"{out}/{name}/sweep.md"))[2:]:
        c = cells(line)
        if c[0] != "nominal":
            continue
        exit_code, walked, heading, err = c[2], c[3], c[4], c[6]
        fall = {"0": "no", "13": "**fell**"}.get(exit_code, f"exit {exit_code}")
        m = re.match(r"([-0-9.]+) / ([0-9.]+) m \((-?[0-9]+) %\)", walked)
        dist = f"{m.group(1)} m ({m.group(3)} %)" if m else walked
        return [fall, dist, heading, err]
    return ["–", "–", "–", "–"]

rows = [
    ("Table 2, the firmware's defaults (closed loop, stretched timing)", "`plans/table2.toml`", "default"),
    ("Table 2, the paper's timing, closed loop", "`--firmware-args feasibility=off`", "paper-timing"),
    ("Table 2, the paper's open loop (TLIPFM)", "`plans/table2-paper.toml`", "paper-open"),
]
summary = [
    "| walk | how | fall | walked (of 0.260 m) | heading drift | true CoP − reference mean \\|e\\| x / y (mm) |",
    "| --- | --- | --- | ---: | ---: | ---: |",
]
for what, how, name in rows:
    summary.append("| " + " | ".join([what, how] + nominal(name)) + " |")

def worst(name):
    """README row of a sweep's worst case (a fall or stop first, then the most goals missed,
    then the largest distance error): its name and the row's cells as `nominal` gives them."""
    best = None
    for line in table(read(f"{out}/{name}/sweep.md"))[2:]:
        c = cells(line)
        m = re.match(r"([-0-9.]+) / ([0-9.]+) m", c[3])
        share = float(m.group(1)) / float(m.group(2)) if m else float("-inf")
        missed = 0 if c[7] == "none" else len(c[7].split(";"))
        key = (c[2] == "0", -missed, -abs(share - 1.0))
        if best is None or key < best[0]:
            best = (key, c)
    if best is None:
        return None
    c = best[1]
    fell = "fell at" in c[7]
    fall = {"0": "no", "13": "**fell**"}.get(c[2], "**fell** " * fell + f"(exit {c[2]})")
    m = re.match(r"([-0-9.]+) / ([0-9.]+) m \((-?[0-9]+) %\)", c[3])
    dist = f"{m.group(1)} m ({m.group(3)} %)" if m else c[3]
    return c[0], [fall, dist, c[4], c[6]]

def worst_row(name, what):
    """The README row of a servo-family sweep's worst case (none when it was not walked)."""
    w = worst(name)
    if w is None:
        return []
    return ["| " + " | ".join([what.format(w[0]), "`walker sweep --family servos`"] + w[1]) + " |"]

summary += worst_row("servos/defaults", "Table 2, the defaults on the servo family's worst case (`{}`)")
summary = "\n".join(summary)
op3 = "\n".join(summary.splitlines()[:2] + [
    "| " + " | ".join(["The OP3's forward walk, the defaults", "`plans/op3-forward.toml`"]
                     + nominal("op3")) + " |",
] + worst_row("op3", "the same on the servo family's worst case (`{}`)"))

commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                        text=True).stdout.strip() or "unknown"
source = os.environ.get("RESULTS_NOTE") or (
    f"Walked by `bash scripts/results.sh` at commit {commit} (MuJoCo 3.17, seed 0; the "
    f"reports are in `{out}/`).")

def section(title, intro, name, file):
    t = table(read(f"{out}/{name}/{file}"))
    body = "\n".join(t) if t else f"(no report in `{out}/{name}/{file}`: not walked)"
    return f"## {title}\n\n{intro}\n\n{body}\n"

def section_all(title, intro, name, file):
    """A section with everything of the report from its first table on."""
    md = read(f"{out}/{name}/{file}")
    i = md.find("\n|") if md else -1
    body = md[i + 1:].strip() if i >= 0 else f"(no report in `{out}/{name}/{file}`: not walked)"
    return f"## {title}\n\n{intro}\n\n{body}\n"

doc = f"""# Current figures

Generated by `bash scripts/results.sh` — do not edit by hand. {source} The firmware walks in
QEMU (`mps2-an500`, Cortex-M7) in lock-step with the MuJoCo robot ([simulation.md](simulation.md));
"true CoP" is the physics' centre of pressure, scored against the firmware's ZMP reference over
the walking ticks (`host/src/beyond.rs` `score`); distance, heading drift and tilt are the
pelvis's, from the simulator's truth (`host/src/fil.rs` `walk_figures`). What each closed-loop
part is: [beyond.md](beyond.md). The targets (the closed-loop goals of `host/src/sweep.rs`):
no fall, ≥ 95 % of the planned distance, heading drift < 3°, true mean |e| < 11 mm sagittal and
< 14 mm lateral (the paper's TLIPFM on its real robot: 11 / 14 mm). History: CHANGELOG.md.

## Summary (the README's table)

{summary}

{section("Robustness sweep (the firmware's defaults)",
         "`walker sweep --plan plans/table2.toml`: the nominal robot and one perturbation of the robot family per row (`host/src/sweep.rs`).",
         "default", "sweep.md")}
{section("Robustness sweep at the paper's timing",
         "`walker sweep --plan plans/table2.toml --firmware-args feasibility=off`.",
         "paper-timing", "sweep.md")}
{section("The paper's open loop across the family",
         "`walker sweep --plan plans/table2-paper.toml` (TLIPFM, the paper's timing, every feedback and feed-forward off, the servos' factory gains).",
         "paper-open", "sweep.md")}
{section("The servo family (the firmware's defaults)",
         "`walker sweep --family servos --plan plans/table2.toml`: the servos a robot of this class really has, one change per row (stall torque, no-load speed, drive gains, supply, masses, the trunk's CoM, friction, sensor and Present Position latency; `host/src/sweep.rs` `servo_cases`).",
         "servos/defaults", "sweep.md")}
{section_all("Which default earns its place: the servo family, one feature off at a time",
         "`walker sweep --family servos --plan plans/table2.toml --ablate`: the family walked with the defaults and once per feature off (`host/src/ablation.rs`); a feature stays on by default only if it is nowhere worse than off — falls first, then the distance (|walked/planned − 1|, 2 % margin) and the true ZMP (1 mm margin).",
         "servos", "ablation.md")}
{section("The servo family, the paper's open loop",
         "`walker sweep --family servos --plan plans/table2-paper.toml`: the same family walked open loop, the baseline the defaults must never fall behind in distance.",
         "servos-open", "sweep.md")}
{section("The closed loop, one part at a time",
         "`walker beyond --ablation --plan plans/table2.toml` (the stretched timing): the three models open loop, then TLIPFM with one part added per row; the row marked (default) is the firmware's default configuration. Distance here is the pelvis's travel between the first and the last gait sample the firmware commanded.",
         "ablation", "beyond.md")}
{section("The ROBOTIS OP3 across the servo family",
         "`walker sweep --family servos --plan plans/op3-forward.toml`: the second robot (gait-core `robot/op3.rs`: Menagerie's op3.xml, its OpenCR's IMU, no foot sensors) on its own plan, the firmware's defaults, the same servo family.",
         "op3", "sweep.md")}
{section("The largest torso push survived",
         "`walker pushes --plan plans/table2.toml`: 10 ms horizontal impulses on the torso, standing (1 s after ready) and walking (6 s into Table 2), climbing until a fall, resolution 0.25 N·s.",
         "pushes", "pushes.md")}"""
with open("docs/results.md", "w", encoding="utf-8") as f:
    f.write(doc)

readme = open("README.md", encoding="utf-8").read()
b, e = "<!-- results:begin -->", "<!-- results:end -->"
i, j = readme.index(b) + len(b), readme.index(e)
readme = readme[:i] + "\n" + summary + "\n" + readme[j:]
b, e = "<!-- op3:begin -->", "<!-- op3:end -->"
i, j = readme.index(b) + len(b), readme.index(e)
readme = readme[:i] + "\n" + op3 + "\n" + readme[j:]
with open("README.md", "w", encoding="utf-8") as f:
    f.write(readme)
print(summary)
print("\nwritten: docs/results.md, README.md")
EOF
