//! The Newton driver's test order: a residual at the round-off of its reference is converged,
//! even when the energy product `|Δu_kᵀ r_k|` of that residual grows (a nearly singular tangent
//! at the converged state), and the energy's divergence test does not overrule it.

use shelldsa::solver::*;

/// One unknown, `r(u, λ) = a (u − λ)` except at the root `u = 1` of the single step to λ = 1,
/// where the residual is `floor` (the round-off left by an assembly) and the tangent `kappa`
/// (nearly singular). From `u = 0` the first update lands exactly on `u = 1`.
struct Scripted {
    a: f64,
    floor: f64,
    kappa: f64,
}

impl NonlinearProblem for Scripted {
    fn n_dofs(&self) -> usize {
        1
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        r[0] = if u[0] == 1.0 {
            self.floor
        } else {
            self.a * (u[0] - load)
        };
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], _load: f64, k: &mut [f64]) -> Result<(), ProblemError> {
        k[0] = if u[0] == 1.0 { self.kappa } else { self.a };
        Ok(())
    }
    fn commit(&mut self, _u: &[f64], _load: f64) {}
    fn restore(&mut self) {}
}

fn run(floor: f64, kappa: f64) -> Result<NewtonReport, Box<NewtonFailure>> {
    let mut p = Scripted {
        a: 1.1e-3,
        floor,
        kappa,
    };
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        // The acceptance and divergence tests themselves: no line search on a diverged iterate.
        options: NewtonOptions {
            line_search: LineSearch::Off,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 1.0,
            // One attempt: a cut step would hide the verdict of the first.
            min_step: 0.9,
            ..Default::default()
        },
    };
    newton.run(&mut p, &pattern, &mut solver, &[0.0])
}

#[test]
fn a_residual_at_roundoff_is_accepted_although_its_energy_grew() {
    // ‖r‖: 1.1e-3 → 6.3e-18 (26 ε of r_ref = 1.1e-3). With κ = 1e-45 the update of that
    // residual is 6.3e27 and |Δu₁ r₁| = 4.0e-35/1e-45 = 4.0e10, 3.6e13 times |Δu₀ r₀| = 1.1e-3:
    // beyond the divergence factor 1e8, which the energy test checked first.
    let report = run(6.3e-18, 1e-45).expect("converged");
    let st = report.converged_steps().next().unwrap();
    assert_eq!(st.residual_norms, vec![1.1e-3, 6.3e-18]);
    assert_eq!(st.acceptance, Some(Acceptance::ResidualRoundoff));
    let growth = st.energy_norms[1] / st.energy_norms[0];
    assert!(growth > 1e8, "energy growth {growth:.3e}");
    assert_eq!(report.u, vec![1.0]);
}

#[test]
fn a_residual_within_tolerance_but_above_roundoff_still_needs_the_energy_test() {
    // ‖r₁‖ = 1e-13 meets rtol·r_ref = 1.1e-11 but not 10³ ε r_ref = 2.4e-16: the iterate is not
    // accepted on its residual; the next update (1e-13/1e-45) throws u far off, where the
    // residual diverges. The energy's growth alone does not end the step while the residual
    // tolerance holds: the failure is the residual's.
    let fail = run(1e-13, 1e-45).unwrap_err();
    let rec = fail.report.attempts.last().unwrap();
    assert_eq!(rec.residual_norms.len(), 3, "{:?}", rec.residual_norms);
    assert!(
        matches!(fail.reason, FailureReason::Diverged { ratio } if ratio > 1e8),
        "{}",
        fail.reason
    );
    assert!(rec.residual_norms[2] > 1e8 * 1.1e-3);
}

#[test]
fn an_energy_growing_above_the_residual_tolerance_is_divergence() {
    // ‖r₁‖ = 1e-6 (above the tolerance 1.1e-11) with κ = 1e-45: |Δu₁ r₁| = 1e33 ≫ 1e8 e₀ is
    // reported as divergence at once (iteration 1), as before.
    let fail = run(1e-6, 1e-45).unwrap_err();
    let rec = fail.report.attempts.last().unwrap();
    assert_eq!(rec.residual_norms, vec![1.1e-3, 1e-6]);
    assert!(
        matches!(fail.reason, FailureReason::Diverged { ratio } if ratio > 1e30),
        "{}",
        fail.reason
    );
}
