// Reduces the per-block partial sums of one window to one (hi, lo) f32 pair per candidate, so
// only 8 bytes per candidate travel back to the host (which adds hi + lo in f64).
// Kahan-compensated over the 2 * n_blocks inputs. Uses the same Params as sweep.wgsl; the host
// prepends `const WG`.

struct Params {
    window_start: u32,
    window_len: u32,
    n_samples: u32,
    block_samples: u32,
    n_blocks: u32,
    stride: u32,
    zero: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> partial: array<vec2<f32>>;
// Bound at this window's offset: out[local] belongs to candidate window_start + local.
@group(0) @binding(2) var<storage, read_write> out: array<vec2<f32>>;

// See sweep.wgsl: keeps the compensation from being simplified away.
fn opaque(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ P.zero);
}

@compute @workgroup_size(WG)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let local = gid.x;
    if local >= P.window_len {
        return;
    }
    var s = 0.0;
    var c = 0.0;
    for (var b = 0u; b < P.n_blocks; b++) {
        let p = partial[b * P.stride + local];
        for (var h = 0u; h < 2u; h++) {
            let y = p[h] - c;
            let t = opaque(s + y);
            c = opaque(t - s) - y;
            s = t;
        }
    }
    out[local] = vec2<f32>(s, -c);
}
