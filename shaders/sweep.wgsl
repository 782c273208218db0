// Correlation sweep and centred sums of squares over candidate monomials, generated on the fly.
//
// The host prepends a block of `const` declarations (see src/engine/gpu/shader.rs):
//   WG      invocations per workgroup
//   R       candidates per invocation
//   CHUNK   samples staged in workgroup memory at a time
//   NZ      number of feature variables
//   TS      factors per sample row of the table (= C(NZ + FD, FD))
//   FD      largest factor degree (1..3)
//   NF      factors per candidate (= ceil(d / FD), at least 1)
//   NW      u32 words per candidate (= ceil(NF / 2); 16-bit factor indices)
//   MODE    0: raw sweep, sum_i x_ij v_i;  1: centred squares, sum_i v_i (x_ij - mean_j)^2
//   LEVEL_END0..3  end (exclusive) of the factors of degree 0..3 in the table
// and replaces the four `//@` lines below with the per-candidate code: R candidates per
// invocation written out as scalars (f0_0, sc0, acc0, ...), or as loops over arrays (the shape
// chosen by `KernelShape::scalar_code`; see docs/gpu.md for what each costs).
//
// How a monomial value is built: for the CHUNK samples in flight the workgroup tabulates every
// monomial of degree <= FD ("factors") once, in workgroup memory. Each candidate is a product of
// NF table entries, so one sample-candidate pair costs NF loads, NF - 1 multiplies and one FMA
// whatever its degree (a degree-9 monomial with FD = 3 is three loads, not nine). Neighbouring
// invocations own neighbouring candidates; in graded-lex order these share their leading
// factors (broadcast loads) and differ in the last one (consecutive table slots, distinct banks).
//
// Precision: products and the CHUNK-long inner sums are f32; each chunk's sum is added into a
// Kahan-compensated (sum, compensation) pair, so a block of thousands of samples loses no more
// than a few f32 ulps of sum_i |x_ij v_i|. The partial pair of every (block, candidate) is
// written out and reduced by finalize.wgsl.

struct Params {
    window_start: u32,   // first candidate of this dispatch window (global index)
    window_len: u32,     // candidates in this window
    n_samples: u32,
    block_samples: u32,  // samples per workgroup row (a multiple of CHUNK)
    n_blocks: u32,
    stride: u32,         // row stride of `partial` (candidates per block row)
    zero: u32,           // 0; see `opaque`
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
// Feature rows, sample-major: z[i * NZ + k].
@group(0) @binding(1) var<storage, read> z: array<f32>;
// The sweep vector (MODE 0) or the weights (MODE 1), one per sample.
@group(0) @binding(2) var<storage, read> v: array<f32>;
// For every factor of degree >= 2: parent factor index (low 16 bits) | variable << 16.
@group(0) @binding(3) var<storage, read> recipe: array<u32>;
// NW words per candidate, 16-bit factor indices, low half first; unused slots are 0 (the factor 1).
@group(0) @binding(4) var<storage, read> cand: array<u32>;
// f32 mean of every candidate (MODE 1 only; MODE 0 binds it but never reads it).
@group(0) @binding(5) var<storage, read> mean: array<f32>;
// (sum, -compensation) per block row and window candidate.
@group(0) @binding(6) var<storage, read_write> partial: array<vec2<f32>>;

var<workgroup> tab: array<f32, CHUNK * TS>;
var<workgroup> vv: array<f32, CHUNK>;

// x, through an integer XOR with P.zero (0 at run time, unknown to the compiler). Kahan's
// compensation (t - s) - y is zero in exact arithmetic, and compilers that reassociate floating
// point (Mesa's NIR does) delete it. Both t and t - s pass through the XOR: with t alone, a
// rewrite of (t - s) - y as t - (s + y) would still give 0, since s + y rounds to t; no float
// rewrite crosses the XOR.
fn opaque(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ P.zero);
}

// Factor q of window candidate `local` (0, the factor 1, for padding candidates).
fn factor_of(local: u32, q: u32) -> u32 {
    if local >= P.window_len {
        return 0u;
    }
    let j = P.window_start + local;
    return (cand[j * NW + q / 2u] >> (16u * (q % 2u))) & 0xffffu;
}

// The mean that MODE 1 subtracts (0 for padding and in MODE 0).
fn mean_of(local: u32) -> f32 {
    if MODE == 1u && local < P.window_len {
        return mean[P.window_start + local];
    }
    return 0.0;
}

// One sample-candidate pair: monomial value p, weight ws.
fn pair(p: f32, ws: f32, mu: f32, acc: f32) -> f32 {
    if MODE == 0u {
        return fma(p, ws, acc);
    }
    let dlt = p - mu;
    return fma(ws * dlt, dlt, acc);
}

// Kahan: adds a chunk's sum into (sum, compensation); the compensation carries the low-order
// part lost by the sum.
fn kahan(sc: vec2<f32>, acc: f32) -> vec2<f32> {
    let y = acc - sc.y;
    let tt = opaque(sc.x + y);
    return vec2<f32>(tt, opaque(tt - sc.x) - y);
}

fn store(b: u32, local: u32, sc: vec2<f32>) {
    if local < P.window_len {
        partial[b * P.stride + local] = vec2<f32>(sc.x, -sc.y);
    }
}

// Factors f0..f1 (one level of degree) of the CHUNK rows, each a lower factor times one
// variable; the (sample, factor) pairs are spread over all invocations.
fn build_level(t: u32, f0: u32, f1: u32) {
    let width = f1 - f0;
    for (var e = t; e < CHUNK * width; e += WG) {
        let row = (e / width) * TS;
        let f = f0 + e % width;
        let rc = recipe[f];
        tab[row + f] = tab[row + (rc & 0xffffu)] * tab[row + 1u + (rc >> 16u)];
    }
}

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let t = lid.x;
    let tile0 = wid.x * (WG * R);
    let b = wid.y;
    let s_begin = b * P.block_samples;
    let s_end = min(s_begin + P.block_samples, P.n_samples);

//@CANDIDATES

    for (var c0 = s_begin; c0 < s_end; c0 += CHUNK) {
        let ns = min(CHUNK, s_end - c0);
        // Degree 0 and 1 factors straight from Z; samples past the end become 0 with weight 0.
        for (var e = t; e < CHUNK * LEVEL_END1; e += WG) {
            let s = e / LEVEL_END1;
            let k = e % LEVEL_END1;
            var val = 0.0;
            if s < ns {
                if k == 0u {
                    val = 1.0;
                } else {
                    val = z[(c0 + s) * NZ + (k - 1u)];
                }
            }
            tab[s * TS + k] = val;
        }
        for (var s = t; s < CHUNK; s += WG) {
            var w = 0.0;
            if s < ns {
                w = v[c0 + s];
            }
            vv[s] = w;
        }
        workgroupBarrier();
        // Degree 2..FD factors (FD is a constant: the barriers stay in uniform control flow).
        if FD >= 2u {
            build_level(t, LEVEL_END1, LEVEL_END2);
            workgroupBarrier();
        }
        if FD >= 3u {
            build_level(t, LEVEL_END2, LEVEL_END3);
            workgroupBarrier();
        }

//@ACCUMULATE
//@KAHAN
        workgroupBarrier();
    }

//@STORE
}
