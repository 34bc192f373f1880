//! Particle sets on a parameter box and their support sizes.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZero;

/// A rectangle `[lo_u, hi_u] × [lo_v, hi_v]` of the parameter domain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamBox {
    /// Lower corner `(u, v)`.
    pub lo: [f64; 2],
    /// Upper corner `(u, v)`.
    pub hi: [f64; 2],
}

impl ParamBox {
    /// The box `[u0, u1] × [v0, v1]`.
    pub fn new(u: [f64; 2], v: [f64; 2]) -> Self {
        ParamBox {
            lo: [u[0], v[0]],
            hi: [u[1], v[1]],
        }
    }
    /// The unit square `[0, 1]²`.
    pub fn unit() -> Self {
        ParamBox {
            lo: [0.0; 2],
            hi: [1.0; 2],
        }
    }
    /// Whether `x` lies in the closed box.
    pub fn contains(&self, x: [f64; 2]) -> bool {
        (0..2).all(|k| x[k] >= self.lo[k] && x[k] <= self.hi[k])
    }
}

/// A parametric edge of a box.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Edge {
    /// `u = u_min`.
    UMin,
    /// `u = u_max`.
    UMax,
    /// `v = v_min`.
    VMin,
    /// `v = v_max`.
    VMax,
}

impl Edge {
    /// All four edges.
    pub const ALL: [Edge; 4] = [Edge::UMin, Edge::UMax, Edge::VMin, Edge::VMax];
}

/// A grid-like particle set: positions (u fastest: index `i + n_u j`), nominal spacing, counts.
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleGrid {
    /// Particle coordinates `(u, v)`.
    pub positions: Vec<[f64; 2]>,
    /// Nominal spacing `(h_u, h_v)`.
    pub spacing: [f64; 2],
    /// `(n_u, n_v)`.
    pub counts: [usize; 2],
}

impl ParticleGrid {
    /// Support half-widths `multiple · (h_u, h_v)` for every particle (the multiple is typically
    /// 2–4; at least about 1.5 for the linear and 2.5 for the quadratic basis near corners).
    pub fn supports(&self, multiple: f64) -> Vec<[f64; 2]> {
        vec![[multiple * self.spacing[0], multiple * self.spacing[1]]; self.positions.len()]
    }
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// No particles.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// Regular `n_u × n_v` grid spanning the box, corners included.
///
/// # Panics
/// If `n_u < 2` or `n_v < 2`, or the box is empty.
pub fn regular_grid(b: ParamBox, n_u: usize, n_v: usize) -> ParticleGrid {
    jittered_grid(b, n_u, n_v, 0.0, 0)
}

/// Jittered (irregular) grid: the regular grid with every coordinate moved by a uniform random
/// amount in `[−jitter · h, jitter · h]` (`h` the spacing of that axis), deterministic for a given
/// `seed`. Particles on an edge of the box stay on it (they move along it only) and the corners
/// stay fixed, so the set still spans the box exactly.
///
/// # Panics
/// If `n_u < 2` or `n_v < 2`, the box is empty, or `jitter` is not in `[0, 0.5)` (at 0.5
/// neighbouring particles could coincide).
pub fn jittered_grid(b: ParamBox, n_u: usize, n_v: usize, jitter: f64, seed: u64) -> ParticleGrid {
    assert!(
        n_u >= 2 && n_v >= 2,
        "particle grid needs at least 2 × 2 particles, got {n_u} × {n_v}"
    );
    assert!(
        b.hi[0] > b.lo[0] && b.hi[1] > b.lo[1],
        "empty parameter box {b:?}"
    );
    assert!(
        (0.0..0.5).contains(&jitter),
        "jitter {jitter} must be in [0, 0.5)"
    );
    let n = [n_u, n_v];
    let h = [
        (b.hi[0] - b.lo[0]) / (n_u - 1) as f64,
        (b.hi[1] - b.lo[1]) / (n_v - 1) as f64,
    ];
    let mut rng = XorShift64::new(seed);
    let mut positions = Vec::with_capacity(n_u * n_v);
    for j in 0..n_v {
        for i in 0..n_u {
            let idx = [i, j];
            let mut p = [0.0; 2];
            for k in 0..2 {
                // The last node is placed at `hi` exactly (no accumulated round-off).
                let base = if idx[k] == n[k] - 1 {
                    b.hi[k]
                } else {
                    b.lo[k] + h[k] * idx[k] as f64
                };
                let on_edge = idx[k] == 0 || idx[k] == n[k] - 1;
                let r = rng.uniform(-1.0, 1.0); // drawn always: the sequence does not depend on edges
                p[k] = if on_edge || jitter == 0.0 {
                    base
                } else {
                    base + r * jitter * h[k]
                };
            }
            positions.push(p);
        }
    }
    ParticleGrid {
        positions,
        spacing: h,
        counts: n,
    }
}

/// Tiny xorshift64* generator: deterministic, seedable, good enough for jitter and test points.
#[derive(Clone, Debug)]
pub struct XorShift64 {
    state: u64,
}

impl XorShift64 {
    /// Seeded generator (any seed, 0 included, is mapped to a non-zero state).
    pub fn new(seed: u64) -> Self {
        // splitmix64 of the seed: decorrelates nearby seeds and never yields the zero state.
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        XorShift64 {
            state: if z == 0 { 0x2545_F491_4F6C_DD1D } else { z },
        }
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `[0, 1)` (53 random bits).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
    /// Uniform point in the box.
    pub fn point_in(&mut self, b: &ParamBox) -> [f64; 2] {
        [
            self.uniform(b.lo[0], b.hi[0]),
            self.uniform(b.lo[1], b.hi[1]),
        ]
    }
}

/// Local particle spacing of a scattered set: for each particle, the mean distance to its `k`
/// nearest other particles (k-d tree, O(n log n)). For a regular grid with `k = 4` this is the grid
/// spacing. Isotropic: for strongly anisotropic sets use the per-axis nominal spacing
/// ([`ParticleGrid::spacing`]) instead. Returns zeros when there are fewer than 2 particles.
pub fn local_spacing(positions: &[[f64; 2]], k: usize) -> Vec<f64> {
    let n = positions.len();
    if n < 2 || k == 0 {
        return vec![0.0; n];
    }
    let k = k.min(n - 1);
    let tree: ImmutableKdTree<f64, 2> = ImmutableKdTree::new_from_slice(positions);
    let qty = NonZero::new(k + 1).expect("k + 1 > 0");
    positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let nn = tree.nearest_n::<SquaredEuclidean>(p, qty);
            let (sum, cnt) = nn
                .iter()
                .filter(|m| m.item as usize != i)
                .take(k)
                .fold((0.0, 0usize), |(s, c), m| (s + m.distance.sqrt(), c + 1));
            if cnt == 0 {
                0.0
            } else {
                sum / cnt as f64
            }
        })
        .collect()
}

/// Support half-widths `multiple · spacing` per particle, from per-particle spacings `(h_u, h_v)`
/// (e.g. `local_spacing(..).map(|h| [h, h])`).
pub fn supports_from_spacing(spacing: &[[f64; 2]], multiple: f64) -> Vec<[f64; 2]> {
    spacing
        .iter()
        .map(|h| [multiple * h[0], multiple * h[1]])
        .collect()
}
