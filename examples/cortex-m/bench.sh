#!/usr/bin/env bash
# Runs every firmware image on the QEMU cores of run-qemu.sh (Cortex-M4F mps2-an386, M7
# mps2-an500, M33 mps2-an505, M0 microbit, M55 mps3-an547) and prints markdown: one table of
# totals (instructions per chunk, the smallest and largest per-input mean, MACs, the ratio to the
# MAC lower bound at 2 MACs per cycle, flash, RAM) and, for policy and transformer, a per-stage
# table from their `-stages` images (same measurement plus the breakdown; the table states both
# totals, and the script fails if a stages image's digest differs from its image's).
#
#   bash examples/cortex-m/bench.sh            # all images: prodmp mlp policy policy16 transformer transformer-student transformer-student16
#   bash examples/cortex-m/bench.sh policy     # a subset
#   FRMD_BENCH_CORES="m4 m33" bash examples/cortex-m/bench.sh policy
#
# Images that do not fit a board are left out (a "-" row): the transformer on M0 and M55, the
# `-stages` images (two policies) on the M0's 16 KiB.
#
# "instructions / (MACs/2)" is QEMU's instruction count divided by the cycles a core retiring two
# multiply-accumulates per cycle (SMLAD) would need at least; 1.0 would be the bound. The MAC
# column counts int8 and f32 multiply-accumulates alike (f32 ones only in decode and the small
# output stages; for policy and transformer the sum of their stages). Each image's raw output is
# kept in $FRMD_BENCH_DIR (default: a temp dir).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
images=("$@")
[ "${#images[@]}" -gt 0 ] || images=(prodmp mlp policy policy16 transformer transformer-student transformer-student16)
read -r -a cores <<<"${FRMD_BENCH_CORES:-m4 m7 m33 m0 m55}"
out_dir="${FRMD_BENCH_DIR:-$(mktemp -d)}"
mkdir -p "$out_dir"

staged=()
for image in "${images[@]}"; do
    case "$image" in policy|policy16|transformer) staged+=("$image") ;; esac
done
fits() { # image core -> whether the image fits the core's board
    case "$1-$2" in
        transformer*-m0|transformer*-m55|*-stages-m0) return 1 ;;
    esac
}
for image in "${images[@]}" "${staged[@]/%/-stages}"; do
    [ -n "$image" ] || continue
    for core in "${cores[@]}"; do
        fits "$image" "$core" || continue
        echo "bench: $image on $core" >&2
        bash "$here/run-qemu.sh" "$core" "$image" >"$out_dir/$image-$core.txt"
    done
done

value() { # file key -> value of the first "key: value" line (empty if none)
    awk -v key="$2: " 'index($0, key) == 1 { print substr($0, length(key) + 1); exit }' "$1"
}

macs_of() { # file -> MACs per chunk: the macs line, else the sum of the stage_macs lines
    local macs
    macs="$(value "$1" macs)"
    if [ -z "$macs" ]; then
        macs="$(awk '/^stage_macs / { sum += $NF; found = 1 } END { if (found) print sum }' "$1")"
    fi
    echo "$macs"
}

ratio() { # instructions macs -> instructions / (macs / 2), or "-"
    awk -v i="$1" -v m="$2" 'BEGIN { if (m > 0) printf "%.2f", i / (m / 2); else print "-" }'
}

echo "| image | core | instructions/chunk | min / max per input | MACs/chunk | instructions / (MACs/2) | flash (bytes) | RAM (bytes) |"
echo "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"
for image in "${images[@]}"; do
    for core in "${cores[@]}"; do
        file="$out_dir/$image-$core.txt"
        if [ ! -f "$file" ]; then
            echo "| $image | $core | - | - | - | - | does not fit | |"
            continue
        fi
        instructions="$(value "$file" instructions)"
        macs="$(macs_of "$file")"
        if [ -z "$macs" ] && [ -f "$out_dir/$image-stages-$core.txt" ]; then
            macs="$(macs_of "$out_dir/$image-stages-$core.txt")"
        fi
        range="$(awk -v a="$(value "$file" instructions_min)" -v b="$(value "$file" instructions_max)" 'BEGIN { printf "%.0f / %.0f", a, b }')"
        echo "| $image | $core | $instructions | $range | ${macs:--} | $(ratio "$instructions" "${macs:-0}") | $(value "$file" flash) | $(value "$file" ram) |"
    done
done

for image in "${staged[@]}"; do
    [ -n "$image" ] || continue
    for core in "${cores[@]}"; do
        [ -f "$out_dir/$image-stages-$core.txt" ] || continue
        plain="$out_dir/$image-$core.txt"
        with_stages="$out_dir/$image-stages-$core.txt"
        for digest in "$(value "$with_stages" digest)" "$(value "$with_stages" stage_digest)"; do
            if [ "$digest" != "$(value "$plain" digest)" ]; then
                echo "bench: $image-stages on $core: digest $digest differs from $image's $(value "$plain" digest)" >&2
                exit 1
            fi
        done
    done
    present=()
    for core in "${cores[@]}"; do
        [ -f "$out_dir/$image-stages-$core.txt" ] && present+=("$core")
    done
    [ "${#present[@]}" -gt 0 ] || continue
    first="$out_dir/$image-stages-${present[0]}.txt"
    echo
    echo "Per-stage breakdown, $image (\`$image-stages\` image; mean instructions per chunk over $(value "$first" stage_calls) calls; its \`instructions:\` $(value "$first" instructions) vs $(value "$out_dir/$image-${present[0]}.txt" instructions) for the $image image on ${present[0]}; digests equal):"
    echo
    header="| stage | MACs"
    rule="| --- | ---:"
    for core in "${present[@]}"; do
        header+=" | instructions $core | / (MACs/2) $core"
        rule+=" | ---: | ---:"
    done
    echo "$header | share |"
    echo "$rule | ---: |"
    total="$(value "$first" stage_sum)"
    while read -r name; do
        row="| $name | $(value "$first" "stage_macs $name")"
        for core in "${present[@]}"; do
            file="$out_dir/$image-stages-$core.txt"
            instructions="$(value "$file" "stage $name")"
            row+=" | $instructions | $(ratio "$instructions" "$(value "$file" "stage_macs $name")")"
        done
        share="$(awk -v i="$(value "$first" "stage $name")" -v t="$total" 'BEGIN { printf "%.1f %%", 100 * i / t }')"
        echo "$row | $share |"
    done < <(awk '/^stage [a-z0-9_]+: / { sub(/^stage /, ""); sub(/:.*/, ""); print }' "$first")
    row="| **sum of stages** | $(macs_of "$first")"
    for core in "${present[@]}"; do
        file="$out_dir/$image-stages-$core.txt"
        row+=" | $(value "$file" stage_sum) | $(ratio "$(value "$file" stage_sum)" "$(macs_of "$file")")"
    done
    echo "$row | 100 % |"
done
echo >&2 "bench: raw outputs in $out_dir"
