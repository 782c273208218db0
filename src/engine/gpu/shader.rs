//! The text of the sweep shader: `shaders/sweep.wgsl` specialised to one problem and one
//! [`KernelShape`].
//!
//! The file holds the structure (the factor table, the chunk loop, the barriers); this module
//! prepends its constants and writes the per-candidate code in place of its four `//@` lines.
//! That code is written out here rather than left to the driver: with R candidates per invocation
//! as scalars (`f3_1`, `acc3`, `sc3`) no compiler has to unroll a loop to keep them in registers;
//! the array form is kept to measure what that buys (docs/gpu.md).

use super::KernelShape;

const SWEEP_WGSL: &str = include_str!("../../../shaders/sweep.wgsl");
const FINALIZE_WGSL: &str = include_str!("../../../shaders/finalize.wgsl");

/// `const NAME: u32 = VALUE;` lines.
fn header(consts: &[(&str, u32)]) -> String {
    consts
        .iter()
        .map(|(k, v)| format!("const {k}: u32 = {v}u;\n"))
        .collect()
}

/// The sweep shader for `mode` (0: raw sweep, 1: centred squares) with the constants `consts`
/// (everything in the header of sweep.wgsl except `WG`, `R` and `MODE`, which come from `shape`
/// and `mode`) and `nf` factors per candidate.
pub(super) fn sweep(consts: &[(&str, u32)], shape: &KernelShape, nf: usize, mode: u32) -> String {
    let mut all = vec![
        ("WG", shape.workgroup),
        ("R", shape.per_invocation),
        ("MODE", mode),
    ];
    all.extend_from_slice(consts);
    let code = if shape.scalar_code {
        scalar_code(shape.per_invocation as usize, nf)
    } else {
        array_code()
    };
    let mut text = header(&all);
    for line in SWEEP_WGSL.lines() {
        match line.trim() {
            "//@CANDIDATES" => text.push_str(&code.candidates),
            "//@ACCUMULATE" => text.push_str(&code.accumulate),
            "//@KAHAN" => text.push_str(&code.kahan),
            "//@STORE" => text.push_str(&code.store),
            _ => {
                text.push_str(line);
                text.push('\n');
            }
        }
    }
    text
}

/// The finalize shader (its own workgroup size).
pub(super) fn finalize(workgroup: u32) -> String {
    format!("{}{FINALIZE_WGSL}", header(&[("WG", workgroup)]))
}

/// The four generated pieces of the sweep shader.
struct CandidateCode {
    /// Before the chunk loop: each candidate's factor indices, mean and (sum, compensation).
    candidates: String,
    /// In the chunk loop, after the table: the chunk's sums.
    accumulate: String,
    /// After them: each chunk sum added into its compensated pair.
    kahan: String,
    /// After the chunk loop: the pairs written out.
    store: String,
}

/// R candidates as scalars: names carry the candidate's index.
fn scalar_code(r: usize, nf: usize) -> CandidateCode {
    let mut c = CandidateCode {
        candidates: String::new(),
        accumulate: String::new(),
        kahan: String::new(),
        store: String::new(),
    };
    for k in 0..r {
        c.candidates
            .push_str(&format!("    let j{k} = tile0 + t + {k}u * WG;\n"));
        for q in 0..nf {
            c.candidates
                .push_str(&format!("    let f{k}_{q} = factor_of(j{k}, {q}u);\n"));
        }
        c.candidates.push_str(&format!(
            "    let mu{k} = mean_of(j{k});\n    var sc{k} = vec2<f32>(0.0, 0.0);\n"
        ));
        c.accumulate
            .push_str(&format!("        var acc{k} = 0.0;\n"));
        c.kahan
            .push_str(&format!("        sc{k} = kahan(sc{k}, acc{k});\n"));
        c.store.push_str(&format!("    store(b, j{k}, sc{k});\n"));
    }
    c.accumulate.push_str(
        "        for (var s = 0u; s < CHUNK; s++) {\n            let row = s * TS;\n            let ws = vv[s];\n",
    );
    for k in 0..r {
        let product: Vec<String> = (0..nf).map(|q| format!("tab[row + f{k}_{q}]")).collect();
        c.accumulate.push_str(&format!(
            "            acc{k} = pair({}, ws, mu{k}, acc{k});\n",
            product.join(" * ")
        ));
    }
    c.accumulate.push_str("        }\n");
    c
}

/// The same code as loops over per-candidate arrays (left to the driver to unroll).
fn array_code() -> CandidateCode {
    CandidateCode {
        candidates: "    var fidx: array<u32, R * NF>;
    var mu: array<f32, R>;
    var sc: array<vec2<f32>, R>;
    for (var r = 0u; r < R; r++) {
        let local = tile0 + t + r * WG;
        for (var q = 0u; q < NF; q++) {
            fidx[r * NF + q] = factor_of(local, q);
        }
        mu[r] = mean_of(local);
        sc[r] = vec2<f32>(0.0, 0.0);
    }
"
        .into(),
        accumulate: "        var acc: array<f32, R>;
        for (var r = 0u; r < R; r++) {
            acc[r] = 0.0;
        }
        for (var s = 0u; s < CHUNK; s++) {
            let row = s * TS;
            let ws = vv[s];
            for (var r = 0u; r < R; r++) {
                var p = tab[row + fidx[r * NF]];
                for (var q = 1u; q < NF; q++) {
                    p = p * tab[row + fidx[r * NF + q]];
                }
                acc[r] = pair(p, ws, mu[r], acc[r]);
            }
        }
"
        .into(),
        kahan: "        for (var r = 0u; r < R; r++) {
            sc[r] = kahan(sc[r], acc[r]);
        }
"
        .into(),
        store: "    for (var r = 0u; r < R; r++) {
        store(b, tile0 + t + r * WG, sc[r]);
    }
"
        .into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn consts() -> Vec<(&'static str, u32)> {
        vec![
            ("CHUNK", 8),
            ("NZ", 3),
            ("TS", 20),
            ("FD", 3),
            ("NF", 2),
            ("NW", 1),
            ("LEVEL_END0", 1),
            ("LEVEL_END1", 4),
            ("LEVEL_END2", 10),
            ("LEVEL_END3", 20),
        ]
    }

    #[test]
    fn every_shape_gives_a_valid_shader() {
        for scalar_code in [true, false] {
            for (workgroup, per_invocation) in [(64, 8), (128, 4), (32, 1)] {
                let shape = KernelShape {
                    workgroup,
                    per_invocation,
                    max_factor_degree: 3,
                    scalar_code,
                    max_chunk: 32,
                };
                for mode in [0, 1] {
                    let text = sweep(&consts(), &shape, 2, mode);
                    assert!(
                        !text.lines().any(|l| l.trim().starts_with("//@")),
                        "a marker was left in the shader"
                    );
                    let module = naga::front::wgsl::parse_str(&text)
                        .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&text)));
                    naga::valid::Validator::new(
                        naga::valid::ValidationFlags::all(),
                        naga::valid::Capabilities::empty(),
                    )
                    .validate(&module)
                    .unwrap_or_else(|e| panic!("{shape:?} mode {mode}: {e:?}"));
                }
            }
        }
        // The scalar form names every candidate's factors and nothing beyond R.
        let shape = KernelShape::default();
        let text = sweep(&consts(), &shape, 2, 0);
        let r = shape.per_invocation as usize;
        assert!(text.contains(&format!("f{}_1", r - 1)) && !text.contains(&format!("f{r}_0")));
    }
}
