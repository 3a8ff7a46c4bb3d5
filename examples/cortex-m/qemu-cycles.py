#!/usr/bin/env python3
"""Estimate Cortex-M4 cycles of the measured calls from an instruction trace of QEMU.

    qemu-cycles.py TRACE ELF [--branch-refill P]

TRACE is the log of `qemu-system-arm ... -d in_asm,exec,nochain -D TRACE` (run-qemu.sh writes it
with FRMD_QEMU_TRACE=TRACE): every translated block is printed once with its instructions
(`IN:`), every execution of a block as a `Trace` line. Counting block executions gives the exact
dynamic instruction mix (what QEMU's TCG plugins libinsn/libhowvec would report; Debian's QEMU
ships without them). Only instructions between the harness's markers `frmd_measure_begin` and
`frmd_measure_end` (around each timed call) are counted; the per-call count is checked against
the firmware's own SysTick measurement.

Cycles follow the Cortex-M4 Technical Reference Manual (r0p1, table 3-1), assuming zero-wait-state
memory for code and data (QEMU's SRAM; on a real part, flash wait states not hidden by a cache or
prefetch add cycles) and no interrupts:
  - data processing, shifts, extends (SXTB16 ...), saturation, multiplies including SMLAD, SMULL,
    SMLAL: 1 cycle; IT: 1 (it can fold into a preceding 16-bit instruction: an upper bound);
  - LDR/LDRB/LDRH/LDRSB/LDRSH, STR/STRB/STRH: 2, but a load or store directly after a load or store
    pipelines to 1 (the manual's "N+1" for neighbouring loads; address dependencies ignored);
  - LDRD/STRD: 3; LDM/STM/PUSH/POP: 1 + N registers (+P when POP loads PC);
  - branches: 1 when not taken, 1 + P when taken (taken = the next executed block starts at the
    target), TBB/TBH 2 + P, BL/BLX/BX 1 + P; P is the pipeline refill, 1 to 3 by the manual (the
    estimate is given for P = 1, 2, 3);
  - FPU: VADD/VSUB/VMUL/VABS/VNEG/VCVT/VCMP/VMOV/VMRS 1, VMLA/VMLS/VFMA/VFMS/VNMLA 3, VDIV/VSQRT 14,
    VLDR/VSTR 2, VLDM/VSTM/VPUSH/VPOP 1 + N;
  - SDIV/UDIV: 2 to 12 by the operands; counted as 12 (upper bound);
  - anything else: 1.
"""
import bisect
import collections
import re
import subprocess
import sys

LOAD_STORE = re.compile(r'^(ldr|str)(b|h|sb|sh|ex|exb|exh)?(\.w)?$')


def base(mnemonic):
    """The mnemonic without condition, width and flag suffixes we do not need."""
    m = mnemonic.lower()
    for suffix in ('.w', '.n'):
        if m.endswith(suffix):
            m = m[:-2]
    return m


def register_count(operands):
    inside = operands[operands.find('{') + 1:operands.find('}')]
    count = 0
    for part in inside.split(','):
        part = part.strip()
        if '-' in part:
            lo, hi = part.split('-')
            count += int(re.sub(r'\D', '', hi)) - int(re.sub(r'\D', '', lo)) + 1
        elif part:
            count += 1
    return count


COND = ('eq', 'ne', 'cs', 'hs', 'cc', 'lo', 'mi', 'pl', 'vs', 'vc', 'hi', 'ls', 'ge', 'lt', 'gt', 'le')


def strip_cond(m):
    """`addne` -> `add` (only when what is left is a known mnemonic shape)."""
    for c in COND:
        if m.endswith(c) and len(m) > len(c) + 1:
            stem = m[:-len(c)]
            if stem in ('b', 'bx', 'add', 'sub', 'mov', 'ldr', 'str', 'and', 'orr', 'eor', 'cmp',
                        'ldrb', 'strb', 'lsl', 'lsr', 'asr', 'rsb', 'mvn', 'bic', 'smlabb',
                        'ldrsb', 'ldrsh', 'ldrh', 'strh', 'movw', 'movt', 'cmn', 'tst', 'smlad',
                        'sxtb16', 'uxtb', 'sxtb', 'ldrd', 'strd', 'adds', 'subs', 'movs') \
                    or stem.startswith('v'):
                return stem
    return m


def cost(mnemonic, operands, prev_memory, refill):
    """(cycles without branch refill, is_memory, kind) of one instruction."""
    m = strip_cond(base(mnemonic))
    if m in ('ldrd', 'strd'):
        return 3, True, 'load/store pair'
    if m in ('ldm', 'ldmia', 'ldmfd', 'stm', 'stmia', 'stmdb', 'stmfd', 'push', 'pop', 'ldmdb'):
        n = register_count(operands)
        extra = refill if m in ('pop', 'ldm', 'ldmia') and 'pc' in operands else 0
        return 1 + n + extra, True, 'load/store multiple'
    if LOAD_STORE.match(m):
        return (1 if prev_memory else 2), True, 'load/store'
    if m in ('vldm', 'vldmia', 'vstm', 'vstmia', 'vstmdb', 'vpush', 'vpop'):
        return 1 + register_count(operands), True, 'fp load/store multiple'
    if m in ('vldr', 'vstr'):
        return 2, True, 'fp load/store'
    if m.startswith('vmla') or m.startswith('vmls') or m.startswith('vfma') or m.startswith('vfms') \
            or m.startswith('vnml') or m.startswith('vfnm'):
        return 3, False, 'fp multiply-accumulate'
    if m.startswith('vdiv') or m.startswith('vsqrt'):
        return 14, False, 'fp divide/sqrt'
    if m.startswith('v'):
        return 1, False, 'fp arithmetic/convert/move'
    if m in ('sdiv', 'udiv'):
        return 12, False, 'divide'
    if m in ('tbb', 'tbh'):
        return 2 + refill, False, 'table branch'
    if m in ('bl', 'blx'):
        return 1 + refill, False, 'call'
    if m == 'bx' and 'lr' in operands:
        return 1 + refill, False, 'return'
    if m in ('smlad', 'smladx', 'smlsd', 'smuad', 'smusd'):
        return 1, False, 'dual multiply-accumulate (SMLAD)'
    if m.startswith('sxtb16') or m.startswith('uxtb16'):
        return 1, False, 'dual extend (SXTB16)'
    if m.startswith('smla') or m.startswith('smul') or m.startswith('umul') or m.startswith('umla') \
            or m in ('mul', 'muls', 'mla', 'mls', 'smmul', 'smmla', 'smmulr'):
        return 1, False, 'multiply'
    if m == 'it' or re.match(r'^it[te]{0,3}$', m):
        return 1, False, 'IT'
    return 1, False, 'other'


def main():
    trace, elf = sys.argv[1], sys.argv[2]
    symbols = subprocess.run(['llvm-nm', elf], capture_output=True, text=True).stdout
    marks = {}
    for line in symbols.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] in ('frmd_measure_begin', 'frmd_measure_end'):
            marks[parts[2]] = int(parts[0], 16) & ~1
    begin, end = marks['frmd_measure_begin'], marks['frmd_measure_end']
    blocks = {}       # host pointer -> [(address, mnemonic, operands)]
    pending = None
    measuring = False
    calls = 0
    executions = collections.Counter()   # (host pointer) -> count inside measurement
    successors = collections.Counter()   # (host pointer, next guest pc) -> count
    previous = None
    with open(trace, errors='replace') as f:
        for line in f:
            if line.startswith('IN:'):
                pending = []
                continue
            if pending is not None and line.startswith('0x'):
                m = re.match(r'0x([0-9a-f]+):\s+(?:[0-9a-f]{4} ){1,2}\s*(\S+)\s*(.*)', line)
                if m:
                    pending.append((int(m.group(1), 16), m.group(2), m.group(3)))
                continue
            if not line.startswith('Trace'):
                continue
            m = re.match(r'Trace \d+: (0x[0-9a-f]+) \[[0-9a-f]+/([0-9a-f]+)/', line)
            host, pc = m.group(1), int(m.group(2), 16)
            if pending is not None:
                blocks[host] = pending
                pending = None
            if pc == begin:
                measuring, calls, previous = True, calls + 1, None
                continue
            if pc == end:
                measuring, previous = False, None
                continue
            if not measuring:
                continue
            executions[host] += 1
            if previous is not None:
                successors[(previous, pc)] += 1
            previous = host
    for refill in (1, 2, 3):
        cycles = 0
        instructions = 0
        by_kind = collections.Counter()
        kind_cycles = collections.Counter()
        for host, count in executions.items():
            prev_memory = False
            for (address, mnemonic, operands) in blocks[host]:
                c, memory, kind = cost(mnemonic, operands, prev_memory, refill)
                prev_memory = memory
                cycles += c * count
                instructions += count
                by_kind[kind] += count
                kind_cycles[kind] += c * count
        # Taken branches: a block ending in a branch whose successor is not the next address.
        taken = 0
        for (host, next_pc), count in successors.items():
            last_address, mnemonic, operands = blocks[host][-1]
            m = strip_cond(base(mnemonic))
            if m in ('b', 'cbz', 'cbnz') or (m.startswith('b') and m[1:] in COND):
                fall_through = {last_address + 2, last_address + 4}
                if next_pc not in fall_through:
                    taken += count
        cycles += taken * refill
        kind_cycles['taken branch refill'] += taken * refill
        if refill == 2:
            print(f"measured calls: {calls}")
            print(f"instructions per call: {instructions / calls:.1f}")
            print(f"taken branches per call: {taken / calls:.1f}")
            print("| class | instructions per call | share | cycles per call (P = 2) |")
            print("| --- | ---: | ---: | ---: |")
            for kind, count in by_kind.most_common():
                print(f"| {kind} | {count / calls:.0f} | {100 * count / instructions:.1f} % | "
                      f"{kind_cycles[kind] / calls:.0f} |")
            print(f"| taken-branch refill | - | - | {kind_cycles['taken branch refill'] / calls:.0f} |")
        print(f"estimated Cortex-M4 cycles per call, P = {refill}: {cycles / calls:.0f} "
              f"({cycles / instructions:.3f} cycles per instruction)")


if __name__ == '__main__':
    main()
