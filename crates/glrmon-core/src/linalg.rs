//! Allocation-free kernels on small column-major matrices stored as slices.
//!
//! nalgebra's dynamic matrices are the storage (`DMatrix::as_slice` is column-major);
//! these loops do the per-sample arithmetic without the per-call overhead and the
//! allocations of the generic operators, which dominate for n, p ≤ 10.

/// The state and output dimensions (n, p) of a computation: known at compile time for
/// the common small channels ([`Fixed`]) or at run time ([`Dynamic`]).
///
/// The kernels below are inlined into code generic over a shape, so with a [`Fixed`]
/// shape every loop bound is a constant and the compiler unrolls the small products
/// completely. The operations and their order are the same for both shapes, so the
/// results are the same bits.
pub(crate) trait Shape: Copy {
    /// n, the state dimension.
    fn n(self) -> usize;
    /// p, the output dimension.
    fn p(self) -> usize;
}

/// n = N, p = P known at compile time.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fixed<const N: usize, const P: usize>;

impl<const N: usize, const P: usize> Shape for Fixed<N, P> {
    #[inline(always)]
    fn n(self) -> usize {
        N
    }
    #[inline(always)]
    fn p(self) -> usize {
        P
    }
}

/// n and p known at run time.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Dynamic {
    pub(crate) n: usize,
    pub(crate) p: usize,
}

impl Shape for Dynamic {
    #[inline(always)]
    fn n(self) -> usize {
        self.n
    }
    #[inline(always)]
    fn p(self) -> usize {
        self.p
    }
}

/// Runs `$body` with `$s` bound to the [`Shape`] of (n, p): [`Fixed`] for n, p ≤ 4,
/// [`Dynamic`] otherwise.
macro_rules! with_shape {
    ($n:expr, $p:expr, |$s:ident| $body:expr) => {{
        use $crate::linalg::{Dynamic, Fixed};
        match ($n, $p) {
            (1, 1) => {
                let $s = Fixed::<1, 1>;
                $body
            }
            (1, 2) => {
                let $s = Fixed::<1, 2>;
                $body
            }
            (1, 3) => {
                let $s = Fixed::<1, 3>;
                $body
            }
            (1, 4) => {
                let $s = Fixed::<1, 4>;
                $body
            }
            (2, 1) => {
                let $s = Fixed::<2, 1>;
                $body
            }
            (2, 2) => {
                let $s = Fixed::<2, 2>;
                $body
            }
            (2, 3) => {
                let $s = Fixed::<2, 3>;
                $body
            }
            (2, 4) => {
                let $s = Fixed::<2, 4>;
                $body
            }
            (3, 1) => {
                let $s = Fixed::<3, 1>;
                $body
            }
            (3, 2) => {
                let $s = Fixed::<3, 2>;
                $body
            }
            (3, 3) => {
                let $s = Fixed::<3, 3>;
                $body
            }
            (3, 4) => {
                let $s = Fixed::<3, 4>;
                $body
            }
            (4, 1) => {
                let $s = Fixed::<4, 1>;
                $body
            }
            (4, 2) => {
                let $s = Fixed::<4, 2>;
                $body
            }
            (4, 3) => {
                let $s = Fixed::<4, 3>;
                $body
            }
            (4, 4) => {
                let $s = Fixed::<4, 4>;
                $body
            }
            (n, p) => {
                let $s = Dynamic { n, p };
                $body
            }
        }
    }};
}
pub(crate) use with_shape;

/// Copies the first `len` values of `src` into `dst` (a constant `len` under a
/// [`Fixed`] shape makes it a few register moves instead of a call).
#[inline(always)]
pub(crate) fn copy_n(dst: &mut [f64], src: &[f64], len: usize) {
    dst[..len].copy_from_slice(&src[..len]);
}

/// Element (i, j) of a column-major matrix with `rows` rows.
#[inline(always)]
pub(crate) fn at(rows: usize, i: usize, j: usize) -> usize {
    i + rows * j
}

/// C = α·op(A)·op(B) + β·C, with op(X) = X or Xᵀ. A is stored `ar`×`ac`, B `br`×`bc`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn gemm(
    alpha: f64,
    a: &[f64],
    (ar, ac): (usize, usize),
    ta: bool,
    b: &[f64],
    (br, bc): (usize, usize),
    tb: bool,
    beta: f64,
    c: &mut [f64],
) {
    let (m, inner) = if ta { (ac, ar) } else { (ar, ac) };
    let (inner_b, n) = if tb { (bc, br) } else { (br, bc) };
    debug_assert_eq!(inner, inner_b);
    debug_assert_eq!(c.len(), m * n);
    for j in 0..n {
        for i in 0..m {
            let mut s = 0.0;
            for l in 0..inner {
                let x = if ta { a[at(ar, l, i)] } else { a[at(ar, i, l)] };
                let y = if tb { b[at(br, j, l)] } else { b[at(br, l, j)] };
                s += x * y;
            }
            let cij = &mut c[at(m, i, j)];
            *cij = if beta == 0.0 {
                alpha * s
            } else {
                alpha * s + beta * *cij
            };
        }
    }
}

/// y = α·A·x + β·y for A `rows`×`cols`.
#[inline(always)]
pub(crate) fn gemv(
    alpha: f64,
    a: &[f64],
    rows: usize,
    cols: usize,
    x: &[f64],
    beta: f64,
    y: &mut [f64],
) {
    for (i, yi) in y.iter_mut().enumerate().take(rows) {
        let mut s = 0.0;
        for (j, xj) in x.iter().enumerate().take(cols) {
            s += a[at(rows, i, j)] * xj;
        }
        *yi = if beta == 0.0 {
            alpha * s
        } else {
            alpha * s + beta * *yi
        };
    }
}

/// Replaces the symmetric `n`×`n` matrix `a` by (A + Aᵀ)/2.
#[inline(always)]
pub(crate) fn symmetrize(a: &mut [f64], n: usize) {
    for j in 0..n {
        for i in (j + 1)..n {
            let v = 0.5 * (a[at(n, i, j)] + a[at(n, j, i)]);
            a[at(n, i, j)] = v;
            a[at(n, j, i)] = v;
        }
    }
}

/// In-place Cholesky factorisation A = L·Lᵀ of a symmetric `n`×`n` matrix; the lower
/// triangle receives L and the strict upper triangle is zeroed.
///
/// Returns `false` (leaving `a` partly overwritten) when A is not positive definite
/// or holds a non-finite value.
#[inline(always)]
pub(crate) fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[at(n, j, j)];
        for k in 0..j {
            d -= a[at(n, j, k)] * a[at(n, j, k)];
        }
        if d.is_nan() || d <= 0.0 || !d.is_finite() {
            return false;
        }
        let ljj = d.sqrt();
        a[at(n, j, j)] = ljj;
        for i in (j + 1)..n {
            let mut s = a[at(n, i, j)];
            for k in 0..j {
                s -= a[at(n, i, k)] * a[at(n, j, k)];
            }
            a[at(n, i, j)] = s / ljj;
        }
        for i in 0..j {
            a[at(n, i, j)] = 0.0;
        }
    }
    true
}

/// Solves L·X = B in place (B is `n`×`cols`, L lower triangular `n`×`n`).
#[inline(always)]
pub(crate) fn solve_lower_in_place(l: &[f64], n: usize, b: &mut [f64], cols: usize) {
    for c in 0..cols {
        for i in 0..n {
            let mut s = b[at(n, i, c)];
            for k in 0..i {
                s -= l[at(n, i, k)] * b[at(n, k, c)];
            }
            b[at(n, i, c)] = s / l[at(n, i, i)];
        }
    }
}

/// Solves X·Lᵀ = B in place for X (B is `rows`×`n`): row by row, Lᵀ upper triangular.
#[inline(always)]
pub(crate) fn solve_right_lower_transpose_in_place(
    l: &[f64],
    n: usize,
    b: &mut [f64],
    rows: usize,
) {
    for r in 0..rows {
        for j in 0..n {
            let mut s = b[at(rows, r, j)];
            for k in 0..j {
                s -= b[at(rows, r, k)] * l[at(n, j, k)];
            }
            b[at(rows, r, j)] = s / l[at(n, j, j)];
        }
    }
}

/// Symmetric eigendecomposition by cyclic Jacobi rotations, allocation-free.
///
/// On entry `a` holds a symmetric `n`×`n` matrix (destroyed); on exit `values` holds
/// the eigenvalues and the columns of `vectors` the orthonormal eigenvectors.
/// Jacobi is slow for large n but accurate for small eigenvalues, which is what the
/// rank decision needs, and it converges in a handful of sweeps for n ≤ 10.
pub(crate) fn jacobi_eigen(a: &mut [f64], n: usize, values: &mut [f64], vectors: &mut [f64]) {
    vectors.iter_mut().for_each(|v| *v = 0.0);
    for i in 0..n {
        vectors[at(n, i, i)] = 1.0;
    }
    for _sweep in 0..64 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for j in 0..n {
            diag += a[at(n, j, j)] * a[at(n, j, j)];
            for i in 0..j {
                off += a[at(n, i, j)] * a[at(n, i, j)];
            }
        }
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in (p + 1)..n {
                let apq = a[at(n, p, q)];
                if apq == 0.0 {
                    continue;
                }
                let app = a[at(n, p, p)];
                let aqq = a[at(n, q, q)];
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let akp = a[at(n, k, p)];
                    let akq = a[at(n, k, q)];
                    a[at(n, k, p)] = c * akp - s * akq;
                    a[at(n, k, q)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let apk = a[at(n, p, k)];
                    let aqk = a[at(n, q, k)];
                    a[at(n, p, k)] = c * apk - s * aqk;
                    a[at(n, q, k)] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let vkp = vectors[at(n, k, p)];
                    let vkq = vectors[at(n, k, q)];
                    vectors[at(n, k, p)] = c * vkp - s * vkq;
                    vectors[at(n, k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    for i in 0..n {
        values[i] = a[at(n, i, i)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn gemm_matches_nalgebra_with_transposes() {
        let a = DMatrix::from_fn(3, 2, |i, j| (i * 2 + j) as f64 + 0.5);
        let b = DMatrix::from_fn(3, 4, |i, j| (i as f64 - j as f64) * 0.25);
        let mut c = vec![0.0; 8];
        gemm(
            1.0,
            a.as_slice(),
            (3, 2),
            true,
            b.as_slice(),
            (3, 4),
            false,
            0.0,
            &mut c,
        );
        assert_eq!(DMatrix::from_column_slice(2, 4, &c), a.transpose() * &b);
        let mut c2 = vec![1.0; 9];
        gemm(
            2.0,
            a.as_slice(),
            (3, 2),
            false,
            a.as_slice(),
            (3, 2),
            true,
            1.0,
            &mut c2,
        );
        let want = &a * a.transpose() * 2.0 + DMatrix::from_element(3, 3, 1.0);
        assert_eq!(DMatrix::from_column_slice(3, 3, &c2), want);
    }

    #[test]
    fn cholesky_and_triangular_solves_invert_spd_matrix() {
        let m = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let mut l = m.clone();
        assert!(cholesky_in_place(l.as_mut_slice(), 3));
        assert!((&l * l.transpose() - &m).amax() < 1e-14);
        let mut x = DMatrix::<f64>::identity(3, 3);
        solve_lower_in_place(l.as_slice(), 3, x.as_mut_slice(), 3);
        assert!((&l * &x - DMatrix::identity(3, 3)).amax() < 1e-14);
        let mut y = DMatrix::from_fn(2, 3, |i, j| (i + j) as f64);
        let b = y.clone();
        solve_right_lower_transpose_in_place(l.as_slice(), 3, y.as_mut_slice(), 2);
        assert!((&y * l.transpose() - b).amax() < 1e-13);
        let mut bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky_in_place(bad.as_mut_slice(), 2));
    }

    #[test]
    fn jacobi_reconstructs_matrix_and_finds_zero_eigenvalue() {
        let v = DMatrix::from_row_slice(3, 1, &[1.0, 2.0, -1.0]);
        let w = DMatrix::from_row_slice(3, 1, &[0.5, 0.0, 1.0]);
        let m = &v * v.transpose() + &w * w.transpose() * 3.0;
        let mut a = m.clone();
        let mut vals = [0.0; 3];
        let mut vecs = DMatrix::<f64>::zeros(3, 3);
        jacobi_eigen(a.as_mut_slice(), 3, &mut vals, vecs.as_mut_slice());
        let d = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&vals));
        assert!((&vecs * d * vecs.transpose() - &m).amax() < 1e-13);
        let min = vals.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(min.abs() < 1e-13, "{vals:?}");
    }
}
