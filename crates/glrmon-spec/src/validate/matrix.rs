//! The matrices of a model: their syntax (scalar, dense, LPV), their shapes, and the
//! covariances' symmetry and definiteness.

use glrmon_core::LpvMatrix;
use nalgebra::DMatrix;

use super::{Validator, join};
use crate::covariance::{self, PSD_TOLERANCE, Verdict};
use crate::limits;
use crate::schema::MatrixSpec;

impl Validator {
    /// A matrix as an [`LpvMatrix`]; `square` gives n for a scalar.
    pub(super) fn matrix(
        &mut self,
        prefix: &str,
        name: &str,
        spec: &MatrixSpec,
        square: Option<usize>,
    ) -> Option<LpvMatrix> {
        let path = join(prefix, &format!("model.{name}"));
        match spec {
            MatrixSpec::Scalar(s) => {
                let Some(n) = square else {
                    self.error(
                        path,
                        "a scalar is only allowed for square matrices whose size is known".into(),
                    );
                    return None;
                };
                if !s.is_finite() {
                    self.error(path, "is not finite".into());
                    return None;
                }
                Some(LpvMatrix::constant(DMatrix::identity(n, n) * *s))
            }
            MatrixSpec::Dense(rows) => self.dense(&path, rows).map(LpvMatrix::constant),
            MatrixSpec::Lpv(table) => {
                let Some(base_rows) = table.get("base") else {
                    self.error(path, "an LPV matrix needs a `base` entry".into());
                    return None;
                };
                let base = self.dense(&format!("{path}.base"), base_rows)?;
                let mut terms = Vec::new();
                for (key, rows) in table {
                    if key == "base" {
                        continue;
                    }
                    let index = key.strip_prefix('p').and_then(|d| d.parse::<usize>().ok());
                    let Some(index) = index else {
                        self.error(
                            format!("{path}.{key}"),
                            "LPV entries are `base` and `p<i>` (scheduling signal i)".into(),
                        );
                        continue;
                    };
                    if index >= limits::MAX_SIGNALS {
                        self.error(
                            format!("{path}.{key}"),
                            format!(
                                "names signal p{index}: at most {} signals (limits::MAX_SIGNALS)",
                                limits::MAX_SIGNALS
                            ),
                        );
                        continue;
                    }
                    let m = self.dense(&format!("{path}.{key}"), rows)?;
                    if m.shape() != base.shape() {
                        self.error(
                            format!("{path}.{key}"),
                            format!(
                                "is {}×{} but base is {}×{}",
                                m.nrows(),
                                m.ncols(),
                                base.nrows(),
                                base.ncols()
                            ),
                        );
                        continue;
                    }
                    terms.push((index, m));
                }
                match LpvMatrix::new(base, terms) {
                    Ok(m) => Some(m),
                    Err(e) => {
                        self.error(path, e.to_string());
                        None
                    }
                }
            }
        }
    }

    pub(super) fn dense(&mut self, path: &str, rows: &[Vec<f64>]) -> Option<DMatrix<f64>> {
        // An empty matrix (`[]`, `[[]]`) is never meant: every matrix of the model has
        // at least one row and one column, and an empty one (`H = []`) would otherwise
        // get through to nalgebra's products unchecked.
        if rows.is_empty() {
            self.error(
                path.to_owned(),
                "has no rows: write it row by row, e.g. [[1.0, 0.0]]".into(),
            );
            return None;
        }
        let cols = rows.first().map_or(0, Vec::len);
        if cols == 0 {
            self.error(
                path.to_owned(),
                "has an empty row 0: every row needs at least one entry".into(),
            );
            return None;
        }
        if rows.len() > limits::MAX_MATRIX_SIDE || cols > limits::MAX_MATRIX_SIDE {
            self.error(
                path.to_owned(),
                format!(
                    "is {}×{}: at most {} rows and columns (limits::MAX_MATRIX_SIDE)",
                    rows.len(),
                    cols,
                    limits::MAX_MATRIX_SIDE
                ),
            );
            return None;
        }
        for (i, r) in rows.iter().enumerate() {
            if r.len() != cols {
                self.error(
                    path.to_owned(),
                    format!("row {i} has {} entries but row 0 has {cols}", r.len()),
                );
                return None;
            }
            if let Some(j) = r.iter().position(|x| !x.is_finite()) {
                self.error(path.to_owned(), format!("entry [{i}][{j}] is not finite"));
                return None;
            }
        }
        Some(DMatrix::from_fn(rows.len(), cols, |i, j| rows[i][j]))
    }

    pub(super) fn shape(
        &mut self,
        prefix: &str,
        name: &str,
        m: &LpvMatrix,
        want: (usize, usize),
        why: &str,
    ) -> bool {
        let got = m.shape();
        if got != want {
            self.error(
                join(prefix, &format!("model.{name}")),
                format!(
                    "is {}×{} but {why} (expected {}×{})",
                    got.0, got.1, want.0, want.1
                ),
            );
            return false;
        }
        true
    }

    /// Symmetric, and positive (semi-)definite. A constant matrix within
    /// [`PSD_TOLERANCE`] of that (a paper's rounded figures) comes back projected, with a
    /// warning, and the caller uses it instead; an LPV matrix is checked at its base
    /// point and used as written (see [`covariance`](mod@covariance)).
    pub(super) fn covariance(
        &mut self,
        prefix: &str,
        name: &str,
        m: &LpvMatrix,
        definite: bool,
    ) -> Option<LpvMatrix> {
        let path = join(prefix, &format!("model.{name}"));
        for (label, mat) in
            std::iter::once(("", m.base())).chain(m.terms().iter().map(|(_, t)| (" term", t)))
        {
            let asym = (mat - mat.transpose()).amax();
            if asym > 1e-9 * mat.amax().max(1e-300) {
                self.error(
                    path.clone(),
                    format!("is not symmetric{label} (max |M − Mᵀ| = {asym:.3e})"),
                );
                return None;
            }
        }
        let kind = if definite {
            "positive definite"
        } else {
            "positive semi-definite"
        };
        if !m.terms().is_empty() {
            // Today's check at the base point: no projection for an LPV matrix.
            let eig = m.base().clone().symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            let bad = if definite {
                !(lo > 1e-12 * hi.abs().max(1e-300) && lo > 0.0)
            } else {
                lo < -1e-9 * hi.abs().max(1e-300)
            };
            if bad {
                self.error(
                    path,
                    format!(
                        "is not {kind} at its base point (smallest eigenvalue {lo:.3e}; an LPV \
                         covariance is used as written, never projected)"
                    ),
                );
            }
            return None;
        }
        match covariance::classify(m.base(), definite) {
            Verdict::Kept => None,
            Verdict::Rejected {
                lambda_min,
                lambda_max,
            } => {
                self.error(
                    path,
                    format!(
                        "is not {kind} (smallest eigenvalue {lambda_min:.3e}, largest \
                         {lambda_max:.3e}; a rounded matrix is accepted down to \
                         −{PSD_TOLERANCE:e} × the spectral radius: give more digits if it was \
                         rounded)"
                    ),
                );
                None
            }
            Verdict::Projected {
                matrix,
                lambda_min,
                lambda_max,
                floor,
                change,
            } => {
                let clip = if definite {
                    format!(
                        "eigenvalues below {PSD_TOLERANCE:e} × λ_max = {floor:.3e} raised to it"
                    )
                } else {
                    "negative eigenvalues set to 0".to_owned()
                };
                self.warn(
                    path,
                    format!(
                        "is not {kind} as written (smallest eigenvalue {lambda_min:.3e}, \
                         largest {lambda_max:.3e}, within the tolerance {PSD_TOLERANCE:e} for \
                         rounded figures): using the nearest {kind} matrix ({clip}; \
                         max |Δ{name}| = {change:.3e})"
                    ),
                );
                Some(LpvMatrix::constant(matrix))
            }
        }
    }
}
