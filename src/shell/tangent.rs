//! The consistent tangent of one in-plane quadrature point with all its thickness layers at
//! once: the same matrix as the layer sum of [`point_tangent`](super::point::point_tangent), to
//! round-off, at a fraction of the cost (docs/shell-formulation.md §5 and §8 item 7).
//!
//! **Layer map.** At a layer ℓ (thickness coordinate ζ_ℓ) every stage of the directional
//! derivative `Ġ → Ḣ → L̇ → Δε̇, ṙ, ½ṙ → Δε̇ˡ → σ̇ˡ → Q̇, σ̇ᵍ → Ṗ` (eqs 42, 47, 50, 54–58 and the
//! rate of `P = w det(J) σᵍ J⁻ᵀ`) is linear in `Ġ`. So `vec Ṗ = 𝒜_ℓ vec Ġ` with a 9×9 matrix
//! `𝒜_ℓ` ([`layer_map`]), found by pushing the 9 unit directions of `Ġ` through the chain:
//! 9 passes per layer instead of one per DOF of the point (about 160).
//!
//! **Thickness moments.** The direction of DOF `(J, c)` is a dyad `Ġ_ℓ = v ⊗ (s₀ + ζ_ℓ s₁)`:
//! - translation `c`: `v = e_c`, `s₀ = (Ψ_J,1, Ψ_J,2, 0)`, `s₁ = 0`;
//! - rotation `γ`: `v = ∂d_J/∂α_γ`, `s₀ = (0, 0, t/2 Ψ_J)`, `s₁ = t/2 (Ψ_J,1, Ψ_J,2, 0)`.
//!
//! The residual row `(I, r)` of the layer is `P_ℓ : (u ⊗ (s̃₀ + ζ_ℓ s̃₁))`, of the same form in
//! the test gradients `Ψ̃_I,α` (Petrov–Galerkin rows), with `u = e_i` or `∂d_I/∂α_b`. With the
//! moments `𝓜_k = Σ_ℓ ζ_ℓᵏ 𝒜_ℓ` (k = 0, 1, 2) and `g_k = vec(v ⊗ s_k)`,
//! `r̃_k = vec(u ⊗ s̃_k)`, the layer sum of the entry is
//! `K[(I, r), (J, c)] = r̃₀·(𝓜₀ g₀ + 𝓜₁ g₁) + r̃₁·(𝓜₁ g₀ + 𝓜₂ g₁)`.
//! The change of the rotation virtual field adds `∂²d_I/∂α_b∂α_γ · m_I` to the diagonal rotation
//! blocks, with `m_I = (Σ_ℓ P_ℓ) s̃₀ + (Σ_ℓ ζ_ℓ P_ℓ) s̃₁` the layer sum of the residual's moment
//! vector.
//!
//! **Cost** per in-plane point with `n` neighbours and `L` layers: `9L` chain passes, then
//! `O(n)` small products to push each row through the moments, then about 21 multiply-adds per
//! row and neighbour column block (4 per entry), independent of `L`. The reference sweep runs
//! `5nL` chain passes and `25n²L` row contractions.

use super::point::{
    ParticleState, PointInput, PointKinematics, PointResult, ShapeData, UnitDirector,
    DOFS_PER_PARTICLE,
};
use super::ShellError;
use crate::kinematics::rotation::{director_derivatives, DirectorDerivatives};
use crate::kinematics::unit_director::{n_prime, n_second, n_third};
use crate::kinematics::{skew, strain_to_vec5, stress_from_vec5, sym, M3};
use crate::material::consistent_tangent;
use nalgebra::DMatrix;
use nalgebra::Vector3;

/// A 9×9 linear map on column-major flattened 3×3 tensors, stored by input:
/// `map[k]` is the image of the `k`-th unit tensor (`k = 3 col + row`).
pub type LayerMap = [[f64; 9]; 9];

/// Entries of the layer-summed column images used by the rows: `vec Y₀` (9) and the first two
/// columns of `Y₁` (6); the third column of `Y₁` meets no residual row.
const NY: usize = 15;

/// The linear map `vec Ġ ↦ vec Ṗ` of one layer: the directional derivative of
/// `P = w det(ⁿ⁺¹J) σᵍ ⁿ⁺¹J⁻ᵀ` (the residual's stress measure) along `Ġ`, with `ⁿ⁺¹J̇ = Ġ`.
/// The stages are those of [`point_tangent`](super::point::point_tangent) (the kernels of
/// `kinematics`), with their direction-independent factors formed once per layer and the unit
/// directions `Ġ = e_i e_jᵀ` exploited:
/// - `Ḣ = Ġ Jⁿ⁻¹`, `L̇ = F½⁻¹ Ḣ F½⁻¹ = (F½⁻¹)_{:i} ⊗ (Jⁿ⁻¹ F½⁻¹)_{j:}`, `F½ = I + ½H` (eqs 56–57);
/// - `Δε̇ = sym L̇`, `Δω̇ = skw L̇`, `ṙ = (I − ½Δω)⁻¹ Δω̇ (I + r)/2`,
///   `½ṙ = (I − ¼Δω)⁻¹ Δω̇ (I + ½r)/4` (eqs 54–55, 58);
/// - `Δε̇ˡ = Ȧ Δε Aᵀ + A Δε̇ Aᵀ + A Δε Ȧᵀ`, `A = Qₙ ½rᵀ`, `Ȧ = Qₙ ½ṙᵀ` (eq 50);
/// - `σ̇ˡ = D^ep Δε̇ˡ` (eq 47), `Q̇ = Qₙ ṙᵀ` (eq 42), `σ̇ᵍ = Q̇ᵀσˡQ + Qᵀσ̇ˡQ + QᵀσˡQ̇` (eq 51);
/// - `Ṗ = w det J [tr(J⁻¹Ġ) σᵍJ⁻ᵀ + σ̇ᵍ J⁻ᵀ − σᵍJ⁻ᵀ Ġᵀ J⁻ᵀ]`.
///
/// Column `k = 3j + i` of the result is the image of `e_i e_jᵀ`.
pub fn layer_map(inp: &PointInput<f64>, res: &PointResult<f64>) -> Result<LayerMap, ShellError> {
    let PointKinematics {
        jn_inv,
        h,
        inc,
        j1_inv,
        det1,
        sigma_g,
        ..
    } = res.kinematics;
    let q_n = inp.history.frame;
    let q1 = res.history.frame;
    let sigma_l = stress_from_vec5(&res.history.material.stress);
    let dep = consistent_tangent(inp.material, &res.return_map);
    let id = M3::identity();
    let fh_inv = inverse(&(id + h * 0.5), "I + ½H (mid-step deformation)")?;
    let jf = jn_inv * fh_inv;
    let w_half_inv = inverse(&(id - inc.domega * 0.5), "I − ½Δω")?;
    let w_quarter_inv = inverse(&(id - inc.domega * 0.25), "I − ¼Δω")?;
    let r_factor = (id + inc.r) * 0.5;
    let r_half_factor = (id + inc.r_half) * 0.25;
    let a = q_n * inc.r_half.transpose();
    let a_t = a.transpose();
    let deps_a_t = inc.deps * a_t;
    let a_deps = a * inc.deps;
    let q1_t = q1.transpose();
    let sigma_l_q1 = sigma_l * q1;
    let q1_t_sigma_l = q1_t * sigma_l;
    let jinv_t = j1_inv.transpose();
    // σ J⁻ᵀ, shared by the volume-change and the J⁻ᵀ-rate terms.
    let s = sigma_g * jinv_t;
    let scale = det1 * inp.weight;
    let mut map = [[0.0; 9]; 9];
    for (k, out) in map.iter_mut().enumerate() {
        let (i, j) = (k % 3, k / 3);
        let l_dot = fh_inv.column(i) * jf.row(j);
        let deps_dot = sym(&l_dot);
        let domega_dot = skew(&l_dot);
        let r_dot = w_half_inv * (domega_dot * r_factor);
        let r_half_dot = w_quarter_inv * (domega_dot * r_half_factor);
        let a_dot = q_n * r_half_dot.transpose();
        let deps_l_dot = a_dot * deps_a_t + a * deps_dot * a_t + a_deps * a_dot.transpose();
        let sigma_l_dot = stress_from_vec5(&(dep * strain_to_vec5(&deps_l_dot)));
        let q1_dot = q_n * r_dot.transpose();
        let sigma_g_dot =
            q1_dot.transpose() * sigma_l_q1 + q1_t * sigma_l_dot * q1 + q1_t_sigma_l * q1_dot;
        // For Ġ = e_i e_jᵀ: tr(J⁻¹Ġ) = (J⁻¹)_ji and σJ⁻ᵀ Ġᵀ J⁻ᵀ = (σJ⁻ᵀ)_{:j} ⊗ (J⁻ᵀ)_{i:}.
        let p_dot =
            (s * j1_inv[(j, i)] + sigma_g_dot * jinv_t - s.column(j) * jinv_t.row(i)) * scale;
        out.copy_from_slice(p_dot.as_slice());
    }
    Ok(map)
}

/// Inverse of a matrix of unit scale that the residual has already inverted (or that is
/// invertible by construction); a failure is reported as a collapsed configuration.
fn inverse(m: &M3<f64>, what: &'static str) -> Result<M3<f64>, ShellError> {
    let det = m.determinant();
    match m.try_inverse() {
        Some(inv) if det > 0.0 => Ok(inv),
        _ => Err(ShellError::NonPositiveJacobian { what, det }),
    }
}

/// Accumulates the layers of one in-plane point and adds their summed consistent tangent
/// (`Σ_ℓ` [`point_tangent`](super::point::point_tangent) over the layers, to round-off) into a local matrix.
///
/// Use: [`ThicknessTangent::new`] with the point's shape functions, neighbour states and DOF
/// increments; [`ThicknessTangent::add_layer`] after each layer's [`point_residual`] (or
/// [`point_residual_with`]); [`ThicknessTangent::add_to`] once at the end.
///
/// [`point_residual`]: super::point::point_residual
/// [`point_residual_with`]: super::point::point_residual_with
#[derive(Clone, Debug)]
pub struct ThicknessTangent<'a> {
    shape: &'a [ShapeData],
    particles: &'a [ParticleState<f64>],
    dirs: Vec<DirectorDerivatives>,
    half_t: f64,
    layers: usize,
    /// `𝓜_k = Σ_ℓ ζ_ℓᵏ 𝒜_ℓ`, k = 0, 1, 2.
    moments: [LayerMap; 3],
    /// `Σ_ℓ P_ℓ`, `Σ_ℓ ζ_ℓ P_ℓ`.
    p_moments: [M3<f64>; 2],
    /// The end-of-step unit director of a normalised director field (the same at every layer).
    unit: Option<UnitDirector<f64>>,
}

impl<'a> ThicknessTangent<'a> {
    /// Start the sum for a point with neighbours `shape`, their committed states `particles`
    /// and the local DOF increments `dofs` (5 per neighbour, as for [`point_residual`]).
    ///
    /// [`point_residual`]: super::point::point_residual
    pub fn new(
        shape: &'a [ShapeData],
        particles: &'a [ParticleState<f64>],
        dofs: &[f64],
    ) -> Result<Self, ShellError> {
        let n = shape.len();
        if particles.len() != n {
            return Err(ShellError::Dimension {
                expected: n,
                got: particles.len(),
            });
        }
        if dofs.len() != DOFS_PER_PARTICLE * n {
            return Err(ShellError::Dimension {
                expected: DOFS_PER_PARTICLE * n,
                got: dofs.len(),
            });
        }
        let dirs = particles
            .iter()
            .zip(dofs.chunks_exact(DOFS_PER_PARTICLE))
            .map(|(p, q)| director_derivatives(&p.d, &p.e[0], &p.e[1], [q[3], q[4]]))
            .collect();
        Ok(ThicknessTangent {
            shape,
            particles,
            dirs,
            half_t: 0.0,
            layers: 0,
            moments: [[[0.0; 9]; 9]; 3],
            p_moments: [M3::zeros(); 2],
            unit: None,
        })
    }

    /// As [`ThicknessTangent::new`] with the director derivatives of the neighbours given
    /// (`crate::kinematics::rotation::director_derivatives` of each neighbour's state and rotation DOFs,
    /// e.g. from a per-particle cache).
    pub fn with_directors(
        shape: &'a [ShapeData],
        particles: &'a [ParticleState<f64>],
        dirs: Vec<DirectorDerivatives>,
    ) -> Result<Self, ShellError> {
        let n = shape.len();
        for got in [particles.len(), dirs.len()] {
            if got != n {
                return Err(ShellError::Dimension { expected: n, got });
            }
        }
        Ok(ThicknessTangent {
            shape,
            particles,
            dirs,
            half_t: 0.0,
            layers: 0,
            moments: [[[0.0; 9]; 9]; 3],
            p_moments: [M3::zeros(); 2],
            unit: None,
        })
    }

    /// Number of layers added.
    pub fn layers(&self) -> usize {
        self.layers
    }

    /// Add one layer: its input (same shape functions, neighbours and thickness as the other
    /// layers) and the result of [`point_residual`] for it with the DOFs given to
    /// [`ThicknessTangent::new`].
    ///
    /// [`point_residual`]: super::point::point_residual
    pub fn add_layer(
        &mut self,
        inp: &PointInput<f64>,
        res: &PointResult<f64>,
    ) -> Result<(), ShellError> {
        let n = self.shape.len();
        if res.residual.len() != DOFS_PER_PARTICLE * n {
            return Err(ShellError::Dimension {
                expected: DOFS_PER_PARTICLE * n,
                got: res.residual.len(),
            });
        }
        // The model passes the very same slices for every layer: compare addresses first.
        let same_shape = std::ptr::eq(inp.shape, self.shape) || inp.shape == self.shape;
        let same_particles =
            std::ptr::eq(inp.particles, self.particles) || inp.particles == self.particles;
        if !(same_shape && same_particles) {
            return Err(ShellError::InvalidInput(format!(
                "layer at ζ = {}: its shape functions or neighbour states differ from those the \
                 thickness tangent was started with (expected the same in-plane point)",
                inp.zeta
            )));
        }
        let half_t = inp.thickness * 0.5;
        if self.layers > 0 && half_t != self.half_t {
            return Err(ShellError::InvalidInput(format!(
                "layer at ζ = {}: thickness = {}, expected {} as in the first layer",
                inp.zeta,
                inp.thickness,
                self.thickness()
            )));
        }
        let a = layer_map(inp, res)?;
        let zeta = inp.zeta;
        let powers = [1.0, zeta, zeta * zeta];
        for (m, &zk) in self.moments.iter_mut().zip(&powers) {
            for (mc, ac) in m.iter_mut().zip(&a) {
                for (x, y) in mc.iter_mut().zip(ac) {
                    *x += y * zk;
                }
            }
        }
        if self.layers == 0 {
            self.unit = res.kinematics.unit_director;
        }
        self.p_moments[0] += res.kinematics.p;
        self.p_moments[1] += res.kinematics.p * zeta;
        self.half_t = half_t;
        self.layers += 1;
        Ok(())
    }

    fn thickness(&self) -> f64 {
        self.half_t * 2.0
    }

    /// Add the layer-summed tangent into `k` (`5n × 5n`, local DOF order as the residual).
    ///
    /// Each row `(I, r)` is first pushed through the transposed moments, giving its row image
    /// `X₀ = 𝓜₀ᵀ r̃₀ + 𝓜₁ᵀ r̃₁`, `X₁ = 𝓜₁ᵀ r̃₀ + 𝓜₂ᵀ r̃₁` (`r̃_k = vec(u ⊗ s̃_k)`), so that
    /// `K[(I, r), (J, c)] = X₀·g₀ + X₁·g₁`. The column dyads `g_k` have 2 (translation) or 9
    /// (rotation) nonzero entries, so a column of `K` is a short combination of row-image
    /// arrays, contiguous along the rows.
    pub fn add_to(&self, k: &mut DMatrix<f64>) -> Result<(), ShellError> {
        let n = self.shape.len();
        let nd = DOFS_PER_PARTICLE * n;
        if k.nrows() != nd || k.ncols() != nd {
            return Err(ShellError::Dimension {
                expected: nd,
                got: if k.nrows() != nd {
                    k.nrows()
                } else {
                    k.ncols()
                },
            });
        }
        self.add_to_slice(k.as_mut_slice())
    }

    /// [`ThicknessTangent::add_to`] into a column-major `5n × 5n` slice (a reused buffer).
    pub fn add_to_slice(&self, k: &mut [f64]) -> Result<(), ShellError> {
        self.add_mapped(None, self.shape.len(), k)
    }

    /// Add the layer-summed tangent mapped to a cell of `n_cell` particles (5 DOFs each) into the
    /// column-major `5 n_cell × 5 n_cell` slice `k`: `K_c = Σ_ab T_aᵀ K_ab T_b`, with neighbour
    /// `a` on the cell's DOF block `slots[a].slot` and `T_a` the identity or, for an image
    /// particle, `diag(Q, det Q I₂)` (its local DOFs are `T_a` times its source's).
    ///
    /// The maps act on the factors rather than on the matrix: the row images of an image
    /// neighbour are transformed and the rows of neighbours sharing a block summed before the
    /// column loop, and an image column's dyad direction `v` becomes `Q e_c` (translations) or
    /// `det Q ∂d/∂α` (rotations). So no neighbour-local matrix is formed.
    pub fn add_to_cell(
        &self,
        slots: &[CellSlot],
        n_cell: usize,
        k: &mut [f64],
    ) -> Result<(), ShellError> {
        if slots.len() != self.shape.len() {
            return Err(ShellError::Dimension {
                expected: self.shape.len(),
                got: slots.len(),
            });
        }
        if let Some(s) = slots.iter().find(|s| s.slot >= n_cell) {
            return Err(ShellError::InvalidInput(format!(
                "cell slot = {}: expected < {n_cell} (the cell's particle count)",
                s.slot
            )));
        }
        self.add_mapped(Some(slots), n_cell, k)
    }

    fn add_mapped(
        &self,
        slots: Option<&[CellSlot]>,
        n_cell: usize,
        k: &mut [f64],
    ) -> Result<(), ShellError> {
        let nr = DOFS_PER_PARTICLE * n_cell;
        if k.len() != nr * nr {
            return Err(ShellError::Dimension {
                expected: nr * nr,
                got: k.len(),
            });
        }
        if self.layers == 0 {
            return Ok(());
        }
        let slot_of = |i: usize| match slots {
            Some(s) => s[i],
            None => CellSlot {
                slot: i,
                image: None,
            },
        };
        let ht = self.half_t;
        let [m0, m1, m2] = &self.moments;
        let unit = self.unit.map(|u| UnitMaps::new(&u, &self.p_moments, ht));
        // The rotation rows' images are linear in the weights `t/2 (Ψ̃,1, Ψ̃,2, Ψ)`: image `o`
        // is `c₀ w₀ + c₁ w₁ + c₂ w₂` with the moments' columns `c` below, formed once per point.
        // With a unit director the rows map u ↦ N′u on t/2 Ψ and t/2 Ψ̃,α, plus t/2 Ψ H(r,α) u on
        // the ζ-moment's column α (module docs), so the maps act on the `c` here too.
        let rot_coef: [[Vector3<f64>; 3]; NY] = std::array::from_fn(|o| {
            let (ma, mb) = if o < 9 {
                (&m0[o], &m1[o])
            } else {
                (&m1[o - 9], &m2[o - 9])
            };
            let c0 = Vector3::new(mb[0], mb[1], mb[2]);
            let c1 = Vector3::new(mb[3], mb[4], mb[5]);
            let c2 = Vector3::new(ma[6], ma[7], ma[8]);
            match &unit {
                None => [c0, c1, c2],
                Some(un) => [
                    un.np * c0,
                    un.np * c1,
                    un.np * c2 + un.h[0] * c0 + un.h[1] * c1,
                ],
            }
        });
        ROW_IMAGES.with(|buf| {
            let mut x = buf.borrow_mut();
            x.clear();
            // Row images, structure of arrays: x[o · nr + R] for the NY entries o that columns
            // meet: X₀ (9 entries) then X₁[0..6]; rows of neighbours sharing a block are summed.
            x.resize(NY * nr, 0.0);
            for (i, (sh, dir)) in self.shape.iter().zip(&self.dirs).enumerate() {
                let cs = slot_of(i);
                let r0 = DOFS_PER_PARTICLE * cs.slot;
                let [t1, t2] = sh.dpsi_test;
                // Translation row e_c: r̃₀ = vec(e_c ⊗ (Ψ̃,1, Ψ̃,2, 0)) has entries c and 3 + c.
                let mut tr = [[0.0; NY]; 3];
                for (c, row) in tr.iter_mut().enumerate() {
                    for (o, mo) in m0.iter().enumerate() {
                        row[o] = mo[c] * t1 + mo[3 + c] * t2;
                    }
                    for (o, mo) in m1[..6].iter().enumerate() {
                        row[9 + o] = mo[c] * t1 + mo[3 + c] * t2;
                    }
                }
                // Rotation row u = ∂d/∂α_b: r̃₀ = vec(u ⊗ (0, 0, t/2 Ψ)) has entries 6 + j,
                // r̃₁ = vec(u ⊗ t/2 (Ψ̃,1, Ψ̃,2, 0)) entries j and 3 + j; `t` maps u to the image.
                let (w0, w1, w2) = (ht * t1, ht * t2, ht * sh.psi);
                let t: [[f64; 3]; NY] = std::array::from_fn(|o| {
                    let [c0, c1, c2] = &rot_coef[o];
                    std::array::from_fn(|j| c0[j] * w0 + c1[j] * w1 + c2[j] * w2)
                });
                let mut u = dir.d_a;
                if let Some((q, det)) = cs.image {
                    // Rows of Tᵀ K: translation row c is Σ_r Q[r, c] (row e_r), rotations × det.
                    let e = tr;
                    for (c, row) in tr.iter_mut().enumerate() {
                        for (o, v) in row.iter_mut().enumerate() {
                            *v = e[0][o] * q[(0, c)] + e[1][o] * q[(1, c)] + e[2][o] * q[(2, c)];
                        }
                    }
                    u = u.map(|v| v * det);
                }
                for (c, row) in tr.iter().enumerate() {
                    for (o, v) in row.iter().enumerate() {
                        x[o * nr + r0 + c] += v;
                    }
                }
                for (b, u) in u.iter().enumerate() {
                    for (o, to) in t.iter().enumerate() {
                        x[o * nr + r0 + 3 + b] += to[0] * u[0] + to[1] * u[1] + to[2] * u[2];
                    }
                }
            }
            if let Some(un) = &unit {
                // Columns of the unit director: the direction v enters as N′v on t/2 Ψ and
                // t/2 Ψ,α and as t/2 Ψ H(r,α) v on the ζ-moment's column α, so each row's
                // entries met by rotation columns are mapped once (N′, H symmetric).
                map_unit_rows(&mut x, nr, un);
                // The unit director couples every pair of rotations through N″ and N‴:
                // K[(I, b), (J, γ)] += a_Ibᵀ [Ψ_I Ψ_J S + Σ_α (Ψ_I Ψ_J,α + Ψ̃_I,α Ψ_J) H(y_α)] v_Jγ,
                // S = H(y₃) + Σ_α T(y_α, r,α), y₃ = t/2 (Σ P)_{:3}, y_α = t/2 (Σ ζP)_{:α}, with
                // a = ∂d/∂α (× det Q for an image) on both sides. As a function of the column
                // this is v_Jγ · (Ψ_J w₃ + Ψ_J,1 w₁ + Ψ_J,2 w₂) with the row's
                // w₃ = Sᵀ Ψ_I a + Σ_α Ψ̃_I,α H(y_α)ᵀ a, w_α = H(y_α)ᵀ Ψ_I a: the form the column
                // loop gives the rotation columns, whose weights are t/2 (Ψ, Ψ,1, Ψ,2). So the
                // w / (t/2) join the row's images 6..15 and the pairs need no loop of their own.
                let inv_ht = 1.0 / ht;
                for (i, (sh, dir)) in self.shape.iter().zip(&self.dirs).enumerate() {
                    let cs = slot_of(i);
                    let det = cs.image.map_or(1.0, |(_, det)| det);
                    let [t1, t2] = sh.dpsi_test;
                    let r0 = DOFS_PER_PARTICLE * cs.slot + 3;
                    for (b, a) in dir.d_a.iter().enumerate() {
                        let a = a * det;
                        let psi = sh.psi * inv_ht;
                        // H(y_α)ᵀ a once each: the rows' w₃ and w_α both take it.
                        let h = [un.hy[0].tr_mul(&a), un.hy[1].tr_mul(&a)];
                        let w = [
                            un.s.tr_mul(&a) * psi + (h[0] * t1 + h[1] * t2) * inv_ht,
                            h[0] * psi,
                            h[1] * psi,
                        ];
                        for (o, wo) in [6, 9, 12].into_iter().zip(&w) {
                            for c in 0..3 {
                                x[(o + c) * nr + r0 + b] += wo[c];
                            }
                        }
                    }
                }
            }
            add_columns(&x, nr, ht, self.shape, &self.dirs, slots, k);
        });
        // Change of the rotation virtual field: ∂²d_I/∂α_b∂α_γ · m_I,
        // m_I = (Σ P) s̃₀ + (Σ ζ P) s̃₁ = t/2 (Ψ (Σ P)_{:3} + Ψ̃,1 (Σ ζP)_{:1} + Ψ̃,2 (Σ ζP)_{:2}).
        // For an image both its rotation rows and columns carry det Q (det² = 1).
        let [p0, p1] = &self.p_moments;
        for (i, (sh, dir)) in self.shape.iter().zip(&self.dirs).enumerate() {
            let cs = slot_of(i);
            let m = (p1.column(0) * sh.dpsi_test[0]
                + p1.column(1) * sh.dpsi_test[1]
                + p0.column(2) * sh.psi)
                * ht;
            let m = match &unit {
                None => m,
                Some(un) => {
                    un.np * m + (un.h[0] * p1.column(0) + un.h[1] * p1.column(1)) * (ht * sh.psi)
                }
            };
            let f = cs.image.map_or(1.0, |(_, det)| det * det);
            let r0 = DOFS_PER_PARTICLE * cs.slot + 3;
            for b in 0..2 {
                for g in 0..2 {
                    k[(r0 + g) * nr + r0 + b] += dir.d_ab[b][g].dot(&m) * f;
                }
            }
        }
        Ok(())
    }
}

/// The rows' images met by rotation columns mapped for a normalised director field, in place:
/// per row `r`, with `x_o` the images `o..o + 3` (entries `o · nr + r`),
/// `x₆ ← N′x₆ + H(r,1) x₉ + H(r,2) x₁₂`, `x₉ ← N′x₉`, `x₁₂ ← N′x₁₂`, rows in vectors of
/// [`W`] (the images are stored structure of arrays). Each entry is formed as nalgebra's
/// matrix–vector product forms it, `(a₀ v₀ + a₁ v₁) + a₂ v₂`, and the three products summed
/// left to right: bitwise the same as those products. Compiled for wider vectors where the
/// processor has them, as [`add_columns`].
fn map_unit_rows(x: &mut [f64], nr: usize, un: &UnitMaps) {
    map_unit_rows_wide(
        x,
        nr,
        &[by_rows(&un.np), by_rows(&un.h[0]), by_rows(&un.h[1])],
    );
}

/// A 3×3 matrix as plain arrays, row by row (`[i][j]` = entry `(i, j)`), as the vector kernels
/// take their small matrices.
fn by_rows(a: &M3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| [a[(i, 0)], a[(i, 1)], a[(i, 2)]])
}

/// The matrices `N′`, `H(r,1)`, `H(r,2)` by rows.
type UnitRowMaps = [[[f64; 3]; 3]; 3];

wide_vectors! {
    fn map_unit_rows_wide(x: &mut [f64], nr: usize, maps: &UnitRowMaps)
        => map_unit_rows_generic, avx512 = map_unit_rows_avx512, avx = map_unit_rows_avx {
        let full = nr - nr % W;
        let mut r = 0;
        while r < full {
            unit_rows::<W>(x, nr, r, maps);
            r += W;
        }
        while r < nr {
            unit_rows::<1>(x, nr, r, maps);
            r += 1;
        }
    }
}

/// Rows `r..r + N` of [`map_unit_rows`].
#[inline(always)]
fn unit_rows<const N: usize>(x: &mut [f64], nr: usize, r: usize, maps: &UnitRowMaps) {
    let ld = |x: &[f64], o: usize| -> [f64; N] {
        let s = &x[o * nr + r..o * nr + r + N];
        std::array::from_fn(|l| s[l])
    };
    let v = |o: usize| -> [[f64; N]; 3] { [ld(x, o), ld(x, o + 1), ld(x, o + 2)] };
    let (x3, x1, x2) = (v(6), v(9), v(12));
    // `a v` by rows: (a_i0 v0 + a_i1 v1) + a_i2 v2.
    let mul = |a: &[[f64; 3]; 3], v: &[[f64; N]; 3], i: usize| -> [f64; N] {
        std::array::from_fn(|l| a[i][0] * v[0][l] + a[i][1] * v[1][l] + a[i][2] * v[2][l])
    };
    let [np, h1, h2] = maps;
    for i in 0..3 {
        let (a, b, c) = (mul(np, &x3, i), mul(h1, &x1, i), mul(h2, &x2, i));
        let y3: [f64; N] = std::array::from_fn(|l| a[l] + b[l] + c[l]);
        let y1 = mul(np, &x1, i);
        let y2 = mul(np, &x2, i);
        for (o, y) in [(6, y3), (9, y1), (12, y2)] {
            x[(o + i) * nr + r..(o + i) * nr + r + N].copy_from_slice(&y);
        }
    }
}

/// The maps of a normalised director field at one in-plane point (module
/// [`crate::kinematics::unit_director`]): `N′`, `H(r,α)`, `H(y_α)` and `S`.
struct UnitMaps {
    np: M3<f64>,
    h: [M3<f64>; 2],
    hy: [M3<f64>; 2],
    s: M3<f64>,
}

impl UnitMaps {
    fn new(u: &UnitDirector<f64>, p: &[M3<f64>; 2], ht: f64) -> Self {
        let (d, l) = (&u.d, u.l);
        let y3: Vector3<f64> = p[0].column(2) * ht;
        let y: [Vector3<f64>; 2] = [p[1].column(0) * ht, p[1].column(1) * ht];
        UnitMaps {
            np: n_prime(d, l),
            h: [n_second(d, l, &u.r_a[0]), n_second(d, l, &u.r_a[1])],
            hy: [n_second(d, l, &y[0]), n_second(d, l, &y[1])],
            s: n_second(d, l, &y3)
                + n_third(d, l, &y[0], &u.r_a[0])
                + n_third(d, l, &y[1], &u.r_a[1]),
        }
    }
}

/// Where a neighbour's DOFs go in a cell ([`ThicknessTangent::add_to_cell`]): its DOF block
/// `slot` (5 DOFs per block) and, for an image particle, the map `(Q, det Q)` of its local DOFs
/// from its source's, `x = diag(Q, det Q I₂) q` (`None`: the identity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellSlot {
    /// Block index in the cell.
    pub slot: usize,
    /// `(Q, det Q)` for an image particle.
    pub image: Option<(M3<f64>, f64)>,
}

thread_local! {
    /// Per-thread row images of [`ThicknessTangent::add_to_cell`] (reused from point to point).
    static ROW_IMAGES: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Rows per block of the column kernel: one 512-bit vector of f64.
const W: usize = 8;

/// The coefficients of one neighbour's 5 columns in the column kernel.
#[derive(Clone, Copy)]
struct ColumnCoefficients {
    /// `Ψ,1`, `Ψ,2`.
    d: [f64; 2],
    /// `t/2 (Ψ, Ψ,1, Ψ,2)`.
    a: [f64; 3],
    /// Rotation column directions `v_γ` (× det Q for an image).
    v: [[f64; 3]; 2],
    /// `Q` of an image (translation column c has direction `Q e_c`).
    q: Option<[[f64; 3]; 3]>,
}

wide_vectors! {
    /// The column loop of [`ThicknessTangent::add_to_cell`]: adds `K[:, (J, c)] = X₀·g₀ + X₁·g₁`
    /// for every neighbour column into the column-major `nr × nr` `data`, from the row images `x`
    /// (NY arrays of length `nr`). On x86-64 processors with AVX-512 or AVX the same code runs
    /// compiled for wider vectors; the operations and their order per entry are the same (Rust
    /// does not contract `a * b + c` into fused multiply-adds), so all builds give bitwise equal
    /// results.
    fn add_columns(
        x: &[f64],
        nr: usize,
        ht: f64,
        shape: &[ShapeData],
        dirs: &[DirectorDerivatives],
        slots: Option<&[CellSlot]>,
        data: &mut [f64],
    ) => add_columns_generic, avx512 = add_columns_avx512, avx = add_columns_avx {
        let xs: [&[f64]; NY] = std::array::from_fn(|o| &x[o * nr..(o + 1) * nr]);
        let full = nr - nr % W;
        for (j, (sh, dir)) in shape.iter().zip(dirs).enumerate() {
            let (slot, image) = match slots {
                Some(s) => (s[j].slot, s[j].image),
                None => (j, None),
            };
            let [d1, d2] = sh.dpsi;
            let det = image.map_or(1.0, |(_, det)| det);
            let cc = ColumnCoefficients {
                d: [d1, d2],
                a: [ht * sh.psi, ht * d1, ht * d2],
                v: dir.d_a.map(|v| {
                    let v = if image.is_some() { v * det } else { v };
                    [v[0], v[1], v[2]]
                }),
                q: image.map(|(q, _)| by_rows(&q)),
            };
            let c0 = DOFS_PER_PARTICLE * slot * nr;
            let block = &mut data[c0..c0 + DOFS_PER_PARTICLE * nr];
            let (k0, rest) = block.split_at_mut(nr);
            let (k1, rest) = rest.split_at_mut(nr);
            let (k2, rest) = rest.split_at_mut(nr);
            let (k3, k4) = rest.split_at_mut(nr);
            let mut ks = [k0, k1, k2, k3, k4];
            let mut r = 0;
            while r < full {
                rows::<W>(&xs, r, &cc, &mut ks);
                r += W;
            }
            while r < nr {
                rows::<1>(&xs, r, &cc, &mut ks);
                r += 1;
            }
        }
    }
}

/// Rows `r..r + N` of one neighbour's 5 columns. Per entry: translation `X₀[c] Ψ,1 + X₀[3+c] Ψ,2`
/// (for an image the three of them combined by `Q`), rotation `Σ_i v_i s_i` with
/// `s_i = X₀[6+i] a₀ + X₁[i] a₁ + X₁[3+i] a₂`.
#[inline(always)]
fn rows<const N: usize>(
    xs: &[&[f64]; NY],
    r: usize,
    cc: &ColumnCoefficients,
    ks: &mut [&mut [f64]; 5],
) {
    let ld = |o: usize| -> [f64; N] {
        let s = &xs[o][r..r + N];
        std::array::from_fn(|l| s[l])
    };
    let [d1, d2] = cc.d;
    let mut out = [[0.0; N]; 5];
    match &cc.q {
        None => {
            for (c, oc) in out.iter_mut().take(3).enumerate() {
                let (p, q) = (ld(c), ld(3 + c));
                for l in 0..N {
                    oc[l] = p[l] * d1 + q[l] * d2;
                }
            }
        }
        Some(qm) => {
            let mut t = [[0.0; N]; 3];
            for (i, ti) in t.iter_mut().enumerate() {
                let (p, q) = (ld(i), ld(3 + i));
                for l in 0..N {
                    ti[l] = p[l] * d1 + q[l] * d2;
                }
            }
            for (c, oc) in out.iter_mut().take(3).enumerate() {
                for l in 0..N {
                    oc[l] = t[0][l] * qm[0][c] + t[1][l] * qm[1][c] + t[2][l] * qm[2][c];
                }
            }
        }
    }
    let [a0, a1, a2] = cc.a;
    let mut s = [[0.0; N]; 3];
    for (i, si) in s.iter_mut().enumerate() {
        let (p, q, u) = (ld(6 + i), ld(9 + i), ld(12 + i));
        for l in 0..N {
            si[l] = p[l] * a0 + q[l] * a1 + u[l] * a2;
        }
    }
    for (g, v) in cc.v.iter().enumerate() {
        for l in 0..N {
            out[3 + g][l] = s[0][l] * v[0] + s[1][l] * v[1] + s[2][l] * v[2];
        }
    }
    for (k, o) in ks.iter_mut().zip(&out) {
        for (kv, ov) in k[r..r + N].iter_mut().zip(o) {
            *kv += ov;
        }
    }
}

/// Drop-in for [`point_tangent`](super::point::point_tangent) (one layer): the same matrix to round-off, through
/// [`ThicknessTangent`].
pub fn point_tangent_fast(
    inp: &PointInput<f64>,
    dofs: &[f64],
    res: &PointResult<f64>,
) -> Result<DMatrix<f64>, ShellError> {
    let mut t = ThicknessTangent::new(inp.shape, inp.particles, dofs)?;
    t.add_layer(inp, res)?;
    let nd = dofs.len();
    let mut k = DMatrix::zeros(nd, nd);
    t.add_to(&mut k)?;
    Ok(k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// The unit director's row map equals the `nalgebra` products it replaces bit for bit
    /// (`N′x₆ + H(r,1) x₉ + H(r,2) x₁₂`, `N′x₉`, `N′x₁₂` per row), in every build, on a row
    /// count that is not a multiple of the vector width, leaving the other images alone.
    #[test]
    fn unit_row_map_equals_the_matrix_products_bitwise() {
        let nr = 5 * 7;
        assert_ne!(nr % W, 0);
        let f = |i: usize| ((i as f64) * 0.617 + 0.3).sin();
        let mat = |k: usize| M3::from_fn(|i, j| f(100 * k + 3 * i + j) * 2.0);
        let un = UnitMaps {
            np: mat(1),
            h: [mat(2), mat(3)],
            hy: [M3::zeros(); 2],
            s: M3::zeros(),
        };
        let x0: Vec<f64> = (0..NY * nr).map(|i| f(i) * 1e2).collect();
        let mut reference = x0.clone();
        for r in 0..nr {
            let at =
                |o: usize| Vector3::new(x0[o * nr + r], x0[(o + 1) * nr + r], x0[(o + 2) * nr + r]);
            let (x3, x1, x2) = (at(6), at(9), at(12));
            let y = [
                un.np * x3 + un.h[0] * x1 + un.h[1] * x2,
                un.np * x1,
                un.np * x2,
            ];
            for (o, y) in [6, 9, 12].into_iter().zip(y) {
                for i in 0..3 {
                    reference[(o + i) * nr + r] = y[i];
                }
            }
        }
        let bits = |a: &[f64]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let mut a = x0.clone();
        map_unit_rows(&mut a, nr, &un);
        assert_eq!(bits(&a), bits(&reference));
        assert_ne!(bits(&a), bits(&x0));
        let maps = [by_rows(&un.np), by_rows(&un.h[0]), by_rows(&un.h[1])];
        let mut b = x0.clone();
        map_unit_rows_generic(&mut b, nr, &maps);
        assert_eq!(bits(&b), bits(&reference));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            let mut c = x0.clone();
            // SAFETY: AVX is available.
            unsafe { map_unit_rows_avx(&mut c, nr, &maps) };
            assert_eq!(bits(&c), bits(&reference));
        }
    }

    /// The AVX-512, AVX and baseline builds of the column loop agree bitwise, with real and
    /// image neighbours, shared blocks and a row count that is not a multiple of the block.
    #[test]
    fn column_loop_builds_agree_bitwise() {
        let n = 7;
        let n_cell = 6;
        let nr = DOFS_PER_PARTICLE * n_cell;
        assert_ne!(nr % W, 0);
        let f = |i: usize| ((i as f64) * 0.731).sin();
        let x: Vec<f64> = (0..NY * nr).map(|i| f(i) * 1e3).collect();
        let shape: Vec<ShapeData> = (0..n)
            .map(|i| ShapeData::new(f(3 * i), [f(3 * i + 1), f(3 * i + 2)]))
            .collect();
        let dirs: Vec<DirectorDerivatives> = (0..n)
            .map(|i| {
                let v = |k: usize| Vector3::new(f(i + k), f(i + k + 1), f(i + k + 2));
                DirectorDerivatives {
                    d: v(0),
                    d_a: [v(3), v(6)],
                    d_ab: [[v(9), v(12)], [v(12), v(15)]],
                }
            })
            .collect();
        // Neighbour 6 is an image of the particle in block 2 (a reflection, det = −1).
        let refl = M3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0);
        let slots: Vec<CellSlot> = (0..n)
            .map(|i| CellSlot {
                slot: if i == 6 { 2 } else { i },
                image: (i == 6).then_some((refl, -1.0)),
            })
            .collect();
        let start: Vec<f64> = (0..nr * nr).map(|i| f(i + 5)).collect();
        let mut a = start.clone();
        add_columns(&x, nr, 0.02, &shape, &dirs, Some(&slots), &mut a);
        let mut b = start.clone();
        add_columns_generic(&x, nr, 0.02, &shape, &dirs, Some(&slots), &mut b);
        assert!(a.iter().zip(&start).any(|(p, q)| p != q));
        assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            let mut c = start.clone();
            // SAFETY: AVX is available.
            unsafe { add_columns_avx(&x, nr, 0.02, &shape, &dirs, Some(&slots), &mut c) };
            assert!(c.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
        }
    }
}
