//! The offline design of the kernel estimator: the coordinates of Li, Boem, Pin &
//! Parisini, (3), that split the state into the part the fault enters and a fault-free
//! part seen through one output, and the observer canonical form (5) of the latter.
//!
//! With x = Tζ, ζ = [ζ₁; ζ₂] (ζ₁ ∈ ℝ^{p⋆}, ζ₂ ∈ ℝ^{n⋆}, n⋆ = n − p⋆) and
//! η = S⁻¹y = [η₁; η₂]:
//! ζ̇₁ = A₁₁ζ₁ + A₁₂ζ₂ + B₁u + E₁f,  ζ̇₂ = A₂₁ζ₁ + A₂₂ζ₂ + B₂u,
//! η₁ = ζ₁ (C₁₁ = I),  η₂ = C₂₂ζ₂.
//! The paper takes T and S from Corless & Tu (1998) without an algorithm; this is
//! their construction by orthogonal factorizations: E = QR gives T₁ = Q and E₁ = R;
//! S_{I,1} = (CQ)⁺ makes C₁₁ = I; S_{I,2} spans the left null space of CQ; T₂ spans
//! the kernel of (CQ)⁺C, so that η₁ does not see ζ₂. Then z = Pζ₂ puts (A₂₂, C₂₂) in
//! observer canonical form: A_c = P A₂₂ P⁻¹ has the coefficients a_{n⋆−1}…a₀ of
//! A₂₂^{n⋆} = Σ aᵢ A₂₂ⁱ in its first column and ones on its superdiagonal, C₂₂P⁻¹ = e₁ᵀ.

use nalgebra::{Complex, DMatrix};

use crate::error::ModelError;

/// Relative tolerance of the rank decisions (singular values below it times the
/// largest count as zero).
pub const RANK_TOLERANCE: f64 = 1e-9;

/// The transformation and the blocks of (3) and (5).
#[derive(Debug, Clone)]
pub struct Decomposition {
    /// p⋆: fault channels (columns of E).
    pub faults: usize,
    /// n⋆ = n − p⋆: the fault-free part's order.
    pub order: usize,
    /// T = [T₁ T₂] (n × n).
    pub t: DMatrix<f64>,
    /// T⁻¹.
    pub t_inv: DMatrix<f64>,
    /// S_{I,1} = (CQ)⁺ (p⋆ × p): ζ₁ = S_{I,1}y.
    pub s1: DMatrix<f64>,
    /// S_{I,2} (1 × p): η₂ = S_{I,2}y.
    pub s2: DMatrix<f64>,
    /// A₁₁ (p⋆ × p⋆).
    pub a11: DMatrix<f64>,
    /// A₁₂ (p⋆ × n⋆).
    pub a12: DMatrix<f64>,
    /// A₂₁ (n⋆ × p⋆).
    pub a21: DMatrix<f64>,
    /// A₂₂ (n⋆ × n⋆).
    pub a22: DMatrix<f64>,
    /// B₁ (p⋆ × l).
    pub b1: DMatrix<f64>,
    /// B₂ (n⋆ × l).
    pub b2: DMatrix<f64>,
    /// C₂₂ (1 × n⋆).
    pub c22: DMatrix<f64>,
    /// E₁ (p⋆ × p⋆, invertible).
    pub e1: DMatrix<f64>,
    /// E₁⁻¹.
    pub e1_inv: DMatrix<f64>,
    /// a₀…a_{n⋆−1}: A₂₂^{n⋆} = Σ aᵢ A₂₂ⁱ (the characteristic polynomial's
    /// coefficients with their signs changed).
    pub a: Vec<f64>,
    /// P: z = Pζ₂ in observer canonical form.
    pub p: DMatrix<f64>,
    /// P⁻¹.
    pub p_inv: DMatrix<f64>,
    /// A_{c21} = PA₂₁.
    pub ac21: DMatrix<f64>,
    /// B_c = PB₂.
    pub bc: DMatrix<f64>,
}

fn condition(condition: &'static str, detail: String) -> ModelError {
    ModelError::Condition { condition, detail }
}

fn numerical_rank(m: &DMatrix<f64>) -> usize {
    let sv = m.singular_values();
    let max = sv.iter().copied().fold(0.0, f64::max);
    sv.iter().filter(|&&s| s > RANK_TOLERANCE * max).count()
}

/// Orthonormal basis of the range of a symmetric projector (its eigenvectors of
/// eigenvalue ≈ 1), `count` columns, each with its largest entry positive.
fn projector_range(projector: &DMatrix<f64>, count: usize) -> DMatrix<f64> {
    let eig = projector.clone().symmetric_eigen();
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let n = projector.nrows();
    let mut basis = DMatrix::zeros(n, count);
    for (c, &i) in order.iter().take(count).enumerate() {
        let mut v = eig.eigenvectors.column(i).into_owned();
        let big = v.iamax();
        if v[big] < 0.0 {
            v.neg_mut();
        }
        basis.set_column(c, &v);
    }
    basis
}

/// (M + Mᵀ)/2: a projector computed in floating point, made exactly symmetric.
fn symmetric_part(m: &DMatrix<f64>) -> DMatrix<f64> {
    (m + m.transpose()) * 0.5
}

impl Decomposition {
    /// Designs T, S, P for ẋ = Ax + Bu + Ef, y = Cx.
    ///
    /// # Errors
    /// [`ModelError::Dimension`] or [`ModelError::NonFinite`] for malformed
    /// matrices; [`ModelError::Condition`] naming the assumption or restriction that
    /// fails: E of full column rank, Assumption 1 (rank CE = rank E), the scalar η₂
    /// (p − p⋆ = 1), n⋆ ≥ 1, Assumption 2 (no invariant zero of [A − λI E; C 0] with
    /// Re λ ≥ 0) and the observability of (A₂₂, C₂₂) the deadbeat estimator needs.
    pub fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        c: &DMatrix<f64>,
        e: &DMatrix<f64>,
    ) -> Result<Self, ModelError> {
        let n = a.nrows();
        let dim = |what: &'static str, detail: String| ModelError::Dimension { what, detail };
        if n == 0 || a.ncols() != n {
            return Err(dim(
                "A",
                format!("is {}×{}, must be square", a.nrows(), a.ncols()),
            ));
        }
        if b.nrows() != n {
            return Err(dim("B", format!("has {} rows, A has {n}", b.nrows())));
        }
        if c.ncols() != n || c.nrows() == 0 {
            return Err(dim(
                "C",
                format!("is {}×{}, needs {n} columns", c.nrows(), c.ncols()),
            ));
        }
        if e.nrows() != n || e.ncols() == 0 {
            return Err(dim(
                "E",
                format!("is {}×{}, needs {n} rows", e.nrows(), e.ncols()),
            ));
        }
        for (what, m) in [("A", a), ("B", b), ("C", c), ("E", e)] {
            if m.iter().any(|x| !x.is_finite()) {
                return Err(ModelError::NonFinite { what });
            }
        }
        let faults = e.ncols();
        let outputs = c.nrows();
        let rank_e = numerical_rank(e);
        if rank_e < faults {
            return Err(condition(
                "E of full column rank (E₁ square and invertible)",
                format!(
                    "E has {faults} columns but rank {rank_e}: two fault channels enter the \
                     state the same way; merge them"
                ),
            ));
        }
        let rank_ce = numerical_rank(&(c * e));
        if rank_ce < rank_e {
            return Err(condition(
                "Assumption 1, rank CE = rank E",
                format!(
                    "rank CE = {rank_ce} < rank E = {rank_e}: some fault direction is not \
                     seen directly by the outputs"
                ),
            ));
        }
        if outputs != faults + 1 {
            return Err(condition(
                "the scalar η₂ of the estimator (p − p⋆ = 1)",
                format!(
                    "the model has p = {outputs} outputs and p⋆ = {faults} fault channels; \
                     the method needs exactly one output more than fault channels"
                ),
            ));
        }
        if n <= faults {
            return Err(condition(
                "n⋆ = n − p⋆ ≥ 1",
                format!(
                    "n = {n} states and p⋆ = {faults} fault channels leave no state to estimate"
                ),
            ));
        }
        let order = n - faults;

        let qr = e.clone().qr();
        let q = qr.q();
        let e1 = qr.r();
        let cq = c * &q;
        let s1 = cq
            .clone()
            .pseudo_inverse(RANK_TOLERANCE)
            .map_err(|m| condition("Assumption 1, rank CE = rank E", m.to_owned()))?;
        let left = DMatrix::identity(outputs, outputs) - &cq * &s1;
        let s2 = projector_range(&symmetric_part(&left), 1).transpose();
        let k = &s1 * c;
        let k_pinv = k
            .clone()
            .pseudo_inverse(RANK_TOLERANCE)
            .map_err(|m| condition("Assumption 1, rank CE = rank E", m.to_owned()))?;
        let kernel = DMatrix::identity(n, n) - &k_pinv * &k;
        let t2 = projector_range(&symmetric_part(&kernel), order);
        let mut t = DMatrix::zeros(n, n);
        t.view_mut((0, 0), (n, faults)).copy_from(&q);
        t.view_mut((0, faults), (n, order)).copy_from(&t2);
        let t_inv = t
            .clone()
            .try_inverse()
            .ok_or_else(|| condition("an invertible T", "[T₁ T₂] is singular".to_owned()))?;
        let at = &t_inv * a * &t;
        let bt = &t_inv * b;
        let a11 = at.view((0, 0), (faults, faults)).into_owned();
        let a12 = at.view((0, faults), (faults, order)).into_owned();
        let a21 = at.view((faults, 0), (order, faults)).into_owned();
        let a22 = at.view((faults, faults), (order, order)).into_owned();
        let b1 = bt.rows(0, faults).into_owned();
        let b2 = bt.rows(faults, order).into_owned();
        let c22 = &s2 * c * &t2;
        let e1_inv = e1.clone().try_inverse().ok_or_else(|| {
            condition(
                "E of full column rank (E₁ square and invertible)",
                "E₁ is singular".into(),
            )
        })?;

        // Observability of (A₂₂, C₂₂): O = [C₂₂; C₂₂A₂₂; …; C₂₂A₂₂^{n⋆−1}].
        let mut obs = DMatrix::zeros(order, order);
        let mut row = c22.clone();
        for i in 0..order {
            obs.set_row(i, &row.row(0));
            row = &row * &a22;
        }
        if numerical_rank(&obs) < order {
            return Err(unobservable(&a22, &c22));
        }
        let a_coef = obs
            .transpose()
            .lu()
            .solve(&row.transpose())
            .ok_or_else(|| condition("observability of (A₂₂, C₂₂)", "O is singular".into()))?;
        let a_coef: Vec<f64> = a_coef.iter().copied().collect();
        let mut ac = DMatrix::zeros(order, order);
        for j in 0..order {
            ac[(j, 0)] = a_coef[order - 1 - j];
            if j + 1 < order {
                ac[(j, j + 1)] = 1.0;
            }
        }
        let mut obs_c = DMatrix::zeros(order, order);
        let mut row_c = DMatrix::zeros(1, order);
        row_c[(0, 0)] = 1.0;
        for i in 0..order {
            obs_c.set_row(i, &row_c.row(0));
            row_c = &row_c * &ac;
        }
        let p = obs_c
            .try_inverse()
            .ok_or_else(|| condition("observability of (A₂₂, C₂₂)", "O_c is singular".into()))?
            * &obs;
        let p_inv = p
            .clone()
            .try_inverse()
            .ok_or_else(|| condition("observability of (A₂₂, C₂₂)", "P is singular".into()))?;
        let ac21 = &p * &a21;
        let bc = &p * &b2;
        Ok(Self {
            faults,
            order,
            t,
            t_inv,
            s1,
            s2,
            a11,
            a12,
            a21,
            a22,
            b1,
            b2,
            c22,
            e1,
            e1_inv,
            a: a_coef,
            p,
            p_inv,
            ac21,
            bc,
        })
    }

    /// The observer canonical A_c = PA₂₂P⁻¹ (5).
    #[must_use]
    pub fn canonical(&self) -> DMatrix<f64> {
        let n = self.order;
        let mut ac = DMatrix::zeros(n, n);
        for j in 0..n {
            ac[(j, 0)] = self.a[n - 1 - j];
            if j + 1 < n {
                ac[(j, j + 1)] = 1.0;
            }
        }
        ac
    }
}

/// The error for an unobservable (A₂₂, C₂₂): its unobservable eigenvalues are the
/// invariant zeros of [A − λI E; C 0] (with ζ₁ = 0 and C₂₂ζ₂ = 0 forced by y = 0, a
/// zero direction is an eigenvector of A₂₂ in the kernel of C₂₂). Unstable ones break
/// Assumption 2; stable ones leave ζ₂ only detectable, and no deadbeat estimate.
fn unobservable(a22: &DMatrix<f64>, c22: &DMatrix<f64>) -> ModelError {
    let n = a22.nrows();
    let zeros: Vec<Complex<f64>> =
        nalgebra::linalg::Schur::try_new(a22.clone(), f64::EPSILON, 10_000)
            .map(|s| s.complex_eigenvalues().iter().copied().collect())
            .unwrap_or_default();
    let scale = a22.norm().max(c22.norm()).max(1.0);
    let mut found = Vec::new();
    for &lambda in &zeros {
        let mut pbh = DMatrix::<Complex<f64>>::zeros(n + 1, n);
        for i in 0..n {
            for j in 0..n {
                pbh[(i, j)] = Complex::new(a22[(i, j)], 0.0);
            }
            pbh[(i, i)] -= lambda;
            pbh[(n, i)] = Complex::new(c22[(0, i)], 0.0);
        }
        let sv = pbh.singular_values();
        if sv.iter().copied().fold(f64::INFINITY, f64::min) < 1e-7 * scale {
            found.push(lambda);
        }
    }
    let list = found
        .iter()
        .map(|z| format!("{:.6}{:+.6}i", z.re, z.im))
        .collect::<Vec<_>>()
        .join(", ");
    if found.iter().any(|z| z.re >= 0.0) {
        condition(
            "Assumption 2, no invariant zero of [A − λI E; C 0] with Re λ ≥ 0",
            format!("invariant zeros at {list}"),
        )
    } else {
        condition(
            "observability of (A₂₂, C₂₂) for the deadbeat estimator",
            format!(
                "the pencil [A − λI E; C 0] has the stable invariant zeros {list}: the \
                 fault-free part is only detectable, and no finite-time estimate exists"
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Li, Boem, Pin & Parisini, Section V.
    pub(crate) fn paper_example() -> [DMatrix<f64>; 4] {
        let a = DMatrix::from_row_slice(
            5,
            5,
            &[
                -0.6344, 0.0022, -0.0001, 0.9871, 0.0010, //
                0.0, -0.2912, 0.1026, 0.0, -0.3707, //
                0.0, -6.2354, -0.4312, 0.0, -4.1270, //
                -0.5971, 0.0003, 0.0001, -0.5099, 0.0006, //
                0.0, -0.4528, -0.0481, 0.0, -0.9513,
            ],
        );
        let b = DMatrix::from_column_slice(5, 1, &[-0.0459, -0.0047, 3.7830, -2.5115, -0.0453]);
        let mut c = DMatrix::zeros(4, 5);
        for i in 0..4 {
            c[(i, i)] = 1.0;
        }
        let e = DMatrix::from_row_slice(
            5,
            3,
            &[
                -0.0395, -0.0133, -1.0, //
                0.0, 0.0031, 0.0, //
                0.0, 1.8255, -0.5, //
                -1.9042, -0.9494, -1.0, //
                0.0, -0.2081, 0.0,
            ],
        );
        [a, b, c, e]
    }

    #[test]
    fn paper_example_has_the_block_form_of_eq_3_to_rounding() {
        let [a, b, c, e] = paper_example();
        let d = Decomposition::new(&a, &b, &c, &e).unwrap();
        assert_eq!((d.faults, d.order), (3, 2));
        let tol = 1e-12;
        // T⁻¹E = [E₁; 0].
        let te = &d.t_inv * &e;
        assert!((te.rows(0, 3) - &d.e1).amax() < tol);
        assert!(te.rows(3, 2).amax() < tol);
        // S⁻¹CT = diag(I, C₂₂).
        let s_inv = DMatrix::from_fn(4, 4, |i, j| if i < 3 { d.s1[(i, j)] } else { d.s2[(0, j)] });
        let sct = &s_inv * &c * &d.t;
        assert!((sct.view((0, 0), (3, 3)) - DMatrix::<f64>::identity(3, 3)).amax() < tol);
        assert!(sct.view((0, 3), (3, 2)).amax() < tol);
        assert!(sct.view((3, 0), (1, 3)).amax() < tol);
        assert!((sct.view((3, 3), (1, 2)) - &d.c22).amax() < tol);
        assert!(s_inv.clone().try_inverse().is_some());
        // T⁻¹AT reassembles from the blocks.
        let at = &d.t_inv * &a * &d.t;
        assert!((at.view((3, 3), (2, 2)) - &d.a22).amax() < tol);
        // (5): PA₂₂P⁻¹ = A_c and C₂₂P⁻¹ = e₁ᵀ.
        assert!((&d.p * &d.a22 * &d.p_inv - d.canonical()).amax() < 1e-10);
        let cp = &d.c22 * &d.p_inv;
        assert!((cp[(0, 0)] - 1.0).abs() < 1e-12 && cp[(0, 1)].abs() < 1e-12);
        // a: the characteristic polynomial s² − a₁s − a₀ of A₂₂.
        let tr = d.a22.trace();
        let det = d.a22.determinant();
        assert!((d.a[1] - tr).abs() < 1e-12 && (d.a[0] + det).abs() < 1e-12);
    }

    #[test]
    fn each_failing_assumption_is_named() {
        let [a, b, c, e] = paper_example();
        // Two equal fault columns.
        let mut e2 = e.clone();
        let col = e2.column(0).into_owned();
        e2.set_column(1, &col);
        let err = Decomposition::new(&a, &b, &c, &e2).unwrap_err().to_string();
        assert!(err.contains("full column rank"), "{err}");
        // Only x0 and x4 measured: rank CE < rank E.
        let c1 = DMatrix::from_row_slice(
            4,
            5,
            &[
                1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0,
                0.0, 0.0, 0.0, 2.0,
            ],
        );
        let err = Decomposition::new(&a, &b, &c1, &e).unwrap_err().to_string();
        assert!(err.contains("Assumption 1"), "{err}");
        // Five outputs for three fault channels.
        let c5 = DMatrix::<f64>::identity(5, 5);
        let err = Decomposition::new(&a, &b, &c5, &e).unwrap_err().to_string();
        assert!(err.contains("p − p⋆ = 1"), "{err}");
        // An unstable invariant zero: x4 does not reach the outputs and grows.
        let mut a_bad = a.clone();
        a_bad[(4, 4)] = 0.5;
        for j in 0..4 {
            a_bad[(j, 4)] = 0.0;
        }
        let e_bad = DMatrix::from_row_slice(
            5,
            3,
            &[
                1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            ],
        );
        let err = Decomposition::new(&a_bad, &b, &c, &e_bad)
            .unwrap_err()
            .to_string();
        assert!(err.contains("Assumption 2") && err.contains("0.5"), "{err}");
        a_bad[(4, 4)] = -0.5;
        let err = Decomposition::new(&a_bad, &b, &c, &e_bad)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("only detectable") && err.contains("-0.5"),
            "{err}"
        );
    }

    #[test]
    fn invariant_zeros_are_the_rank_drops_of_the_pencil() {
        // Independent check of the zero characterisation used above: for the paper's
        // example the pencil [A − λI E; C 0] has full column rank n + p⋆ at every
        // eigenvalue of A₂₂ (no zeros) and at random λ.
        let [a, _, c, e] = paper_example();
        let d = Decomposition::new(&a, &DMatrix::zeros(5, 1), &c, &e).unwrap();
        let eig = nalgebra::linalg::Schur::new(d.a22.clone()).complex_eigenvalues();
        for lambda in eig
            .iter()
            .copied()
            .chain([Complex::new(0.3, 1.1), Complex::new(-2.0, 0.0)])
        {
            let mut m = DMatrix::<Complex<f64>>::zeros(9, 8);
            for i in 0..5 {
                for j in 0..5 {
                    m[(i, j)] = Complex::new(a[(i, j)], 0.0);
                }
                m[(i, i)] -= lambda;
                for j in 0..3 {
                    m[(i, 5 + j)] = Complex::new(e[(i, j)], 0.0);
                }
            }
            for i in 0..4 {
                m[(5 + i, i)] = Complex::new(1.0, 0.0);
            }
            let sv = m.singular_values();
            assert!(
                sv.iter().copied().fold(f64::INFINITY, f64::min) > 1e-3,
                "λ = {lambda}"
            );
        }
    }
}
