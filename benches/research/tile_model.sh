#!/bin/sh
# Builds and runs the C models behind the tile kernel's design (docs/method/regression.md,
# "Nodes times triples"): the broadcast tile's share of the FMA rate, then the node x triple sweep
# in its variants. Needs gcc and an AVX-512 CPU; about a minute.
set -e
dir=$(mktemp -d)
src="$(dirname "$0")"
gcc -O3 -march=native -o "$dir/peak" "$src/tile_peak.c"
for a in "256 1 20000" "256 8 3000" "256 32 1000" "32 1 100000"; do "$dir/peak" $a; done
gcc -O3 -march=native -o "$dir/m4" "$src/tile_model.c"
gcc -O3 -march=native -DNRM=6 -o "$dir/m6" "$src/tile_model.c"
gcc -O3 -march=native -DB=512 -o "$dir/m512" "$src/tile_model.c"
for i in 1 2 3; do
    printf 'stored triples, 4 x 4: '; "$dir/m4" 20 2>/dev/null | tail -1
    printf 'forming only:          '; NOTILES=1 "$dir/m4" 20 2>/dev/null | tail -1
    printf 'late triples, 4 x 4:   '; LATE=1 "$dir/m4" 20 2>/dev/null | tail -1
    printf 'late triples, 4 x 6:   '; LATE=1 "$dir/m6" 20 2>/dev/null | tail -1
    printf 'late, blocks of 512:   '; LATE=1 "$dir/m512" 20 2>/dev/null | tail -1
done
rm -r "$dir"
