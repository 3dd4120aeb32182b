#!/usr/bin/env python3
"""Static throughput of a hot loop in a release binary, by llvm-mca.

On machines without hardware counters (most VMs) and with noisy timings,
the model separates changes of a few per cent that timings cannot. It
reads the loop as `objdump -d` prints it, drops calls, points every branch
at one label and asks llvm-mca for the cycles per iteration (one sample,
for the per-sample loops of docs/performance.md).

  benches/loop_mca.py BINARY --at ADDRESS [--mcpu cascadelake]
  benches/loop_mca.py BINARY --function REGEX [--mcpu cascadelake]

--at: an address inside the loop (e.g. the hottest line of `perf annotate`):
the smallest loop that holds it. --function: the largest loop inside the
functions whose demangled name matches. Needs binutils' objdump and LLVM's
llvm-mca; not needed by CI or the tests.
"""
import argparse
import re
import subprocess
import sys

LINE = re.compile(r"^\s+([0-9a-f]+):\t(\S+)\s*(.*)$")
FUNC = re.compile(r"^([0-9a-f]+) <(.*)>:$")


def disassemble(binary):
    out = subprocess.run(
        ["objdump", "-d", "-C", "--no-show-raw-insn", binary],
        capture_output=True, text=True, check=True,
    ).stdout
    func, lines = None, []
    for line in out.splitlines():
        m = FUNC.match(line)
        if m:
            func = m.group(2)
            continue
        m = LINE.match(line)
        if m:
            lines.append((int(m.group(1), 16), m.group(2), m.group(3), func))
    return lines


def loops(lines):
    """(start, end, function) of every backward conditional branch."""
    for addr, op, arg, func in lines:
        if op.startswith("j") and op != "jmp":
            m = re.match(r"([0-9a-f]+)", arg)
            if m and int(m.group(1), 16) < addr:
                yield int(m.group(1), 16), addr, func


def body(lines, start, end):
    text = ["L0:"]
    for addr, op, arg, _ in lines:
        if start <= addr <= end and op != "call" and not op.startswith("nop"):
            arg = re.sub(r"\s*#.*$", "", arg)
            arg = re.sub(r"\s*<[^>]*>", "", arg)
            if op.startswith("j"):
                arg = "L0"
            if op in ("data16", "cs", "ds", "rex.R", "(bad)") or op.startswith("."):
                continue
            text.append(f"{op} {arg}".strip())
    return "\n".join(text) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("binary")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--at", help="an address inside the loop (hex)")
    g.add_argument("--function", help="regex on the demangled function name")
    p.add_argument("--mcpu", default="cascadelake")
    a = p.parse_args()
    lines = disassemble(a.binary)
    found = list(loops(lines))
    if a.at:
        x = int(a.at, 16)
        inside = [l for l in found if l[0] <= x <= l[1]]
        pick = min(inside, key=lambda l: l[1] - l[0], default=None)
    else:
        r = re.compile(a.function)
        inside = [l for l in found if l[2] and r.search(l[2])]
        pick = max(inside, key=lambda l: l[1] - l[0], default=None)
    if pick is None:
        sys.exit("no loop found")
    start, end, func = pick
    print(f"loop {start:#x}..{end:#x} ({end - start} bytes) in {func[:100]}")
    mca = subprocess.run(
        ["llvm-mca", f"-mcpu={a.mcpu}", "-iterations=200", "-resource-pressure"],
        input=body(lines, start, end), capture_output=True, text=True,
    )
    if mca.returncode != 0:
        sys.exit(mca.stderr)
    out = mca.stdout.splitlines()
    for line in out:
        if line.startswith(("Instructions:", "Total uOps:", "Block RThroughput:")):
            print(line)
    names = {}
    for line in out:
        m = re.match(r"^\[(\d+)\]\s+- (\S+)$", line)
        if m:
            names[m.group(1)] = m.group(2)
    for i, line in enumerate(out):
        if line.startswith("Resource pressure per iteration:"):
            heads = re.findall(r"\[(\d+)\]", out[i + 1])
            cycles = out[i + 2].split()
            print("Resource pressure per iteration (cycles):")
            for h, c in zip(heads, cycles):
                print(f"  {names.get(h, h):<16} {c}")
            break


if __name__ == "__main__":
    try:
        main()
    except BrokenPipeError:  # piped into head
        sys.exit(0)
