//! Shifted responses as the columns of an operator: the per-pixel dictionary in which a
//! reflector at a continuous depth is (nearly) one column.
//!
//! Pixel p's atom c is the voxel column g(k − c/Q) of the response g at depth c/Q bins,
//! c = 0 … (K_s − 1)·Q, scaled to unit norm (so that the solvers' correlations compare depths
//! fairly: a triangle between two bins has less energy than one on a bin): Q atoms per bin. [`Atoms`] applies A·D, D the block-diagonal
//! dictionary, so that the per-pixel solvers, which pick one column per pixel, pick one
//! reflector at a depth within 1/(2Q) bin of the truth; a continuous fit then removes the rest.

use crate::error::{Error, Result};
use crate::lidar::Response;
use crate::linalg::dot;
use crate::operator::{LinearOperator, SparseMatrix, VoxelOperator};
use crate::real::Real;
use crate::space::Space;

/// The share of an atom's peak below which its tails are left out: the atoms pick each pixel's
/// depth to a fraction of a bin, which the continuous fit under the whole response then
/// refines, and the work of every application is proportional to the voxels the atoms span
/// (gaussian:0.8 spans 11 bins to its cut-off and 5 above 1% of its peak).
const ATOM_TAIL: f64 = 1e-2;

/// The atoms of one pixel: for each, the first voxel it fills and its values there.
#[derive(Debug, Clone)]
pub(crate) struct Dictionary {
    /// Atoms per bin.
    pub q: usize,
    /// Voxels per pixel (K_s).
    pub ks: usize,
    /// Per atom, (first voxel, values of unit norm).
    atoms: Vec<(usize, Vec<f64>)>,
    /// Per atom, the norm of the response's column it was scaled from.
    norms: Vec<f64>,
}

impl Dictionary {
    /// The atoms of `response` on columns of `ks` voxels, `q` per bin.
    pub fn new(response: &Response, ks: usize, q: usize) -> Dictionary {
        let count = (ks - 1) * q + 1;
        let mut norms = Vec::with_capacity(count);
        let atoms = (0..count)
            .map(|c| {
                let d = c as f64 / q as f64;
                let span = response.voxels(d, ks);
                let mut values: Vec<f64> =
                    span.clone().map(|k| response.value(k as f64 - d)).collect();
                // The tails below ATOM_TAIL of the peak are left out.
                let peak = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let keep = |v: &f64| v.abs() >= ATOM_TAIL * peak;
                let first = values.iter().position(keep).unwrap_or(0);
                let last = values.iter().rposition(keep).map_or(0, |i| i + 1);
                values = values[first..last.max(first)].to_vec();
                let span = span.start + first..span.start + last.max(first);
                let norm = dot(&values, &values).sqrt();
                if norm > 0.0 {
                    values.iter_mut().for_each(|v| *v /= norm);
                }
                norms.push(norm);
                (span.start, values)
            })
            .collect();
        Dictionary {
            q,
            ks,
            atoms,
            norms,
        }
    }

    /// The amplitude of a reflector whose atom `c` has the weight `z`.
    pub fn amplitude(&self, c: usize, z: f64) -> f64 {
        if self.norms[c] > 0.0 {
            z / self.norms[c]
        } else {
            0.0
        }
    }

    /// Atoms per pixel.
    pub fn len(&self) -> usize {
        self.atoms.len()
    }

    /// The depth of atom `c`, in bins.
    pub fn depth(&self, c: usize) -> f64 {
        c as f64 / self.q as f64
    }

    /// Atom `c`: its first voxel and values.
    pub fn atom(&self, c: usize) -> (usize, &[f64]) {
        let (start, v) = &self.atoms[c];
        (*start, v)
    }

    /// Adds `a` times atom `c` to the voxel column `col`.
    fn add(&self, c: usize, a: f64, col: &mut [f64]) {
        let (start, v) = self.atom(c);
        for (x, g) in col[start..].iter_mut().zip(v) {
            *x += a * g;
        }
    }

    /// ⟨atom c, col⟩.
    fn inner(&self, c: usize, col: &[f64]) -> f64 {
        let (start, v) = self.atom(c);
        dot(v, &col[start..start + v.len()])
    }
}

/// A·D: the operator `inner` (pixels of K_s voxels) on the atoms of `dict`.
pub(crate) struct Atoms<'a, T: Real, A: VoxelOperator<T> + ?Sized> {
    inner: &'a A,
    dict: &'a Dictionary,
    pixels: usize,
    _t: std::marker::PhantomData<T>,
}

impl<'a, T: Real, A: VoxelOperator<T> + ?Sized> Atoms<'a, T, A> {
    /// The atoms of `dict` through `inner`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `inner`'s pixels are not of `dict`'s K_s voxels.
    pub fn new(inner: &'a A, dict: &'a Dictionary) -> Result<Self> {
        if inner.column_len() != dict.ks || inner.ncols() % dict.ks != 0 {
            return Err(Error::param(
                "kernel",
                format!(
                    "the operator's pixels of {} voxels are not the dictionary's {}",
                    inner.column_len(),
                    dict.ks
                ),
            ));
        }
        Ok(Atoms {
            inner,
            dict,
            pixels: inner.ncols() / dict.ks,
            _t: std::marker::PhantomData,
        })
    }

    /// The voxels D·z of the atom amplitudes `z`.
    pub fn voxels(&self, z: &[T]) -> Vec<T> {
        let (ks, l) = (self.dict.ks, self.dict.len());
        let mut x = vec![0.0f64; self.pixels * ks];
        for (col, zp) in x.chunks_mut(ks).zip(z.chunks(l)) {
            for (c, a) in zp.iter().enumerate().filter(|(_, a)| **a != T::zero()) {
                self.dict.add(c, a.as_f64(), col);
            }
        }
        x.into_iter().map(T::of_f64).collect()
    }

    /// Dᵀu of the voxel values `u`.
    fn atoms_of(&self, u: &[T], z: &mut [T]) {
        let (ks, l) = (self.dict.ks, self.dict.len());
        let mut col = vec![0.0f64; ks];
        for (up, zp) in u.chunks(ks).zip(z.chunks_mut(l)) {
            for (c, v) in col.iter_mut().zip(up) {
                *c = v.as_f64();
            }
            for (c, zc) in zp.iter_mut().enumerate() {
                *zc = T::of_f64(self.dict.inner(c, &col));
            }
        }
    }

    /// The voxels atom `c` (a flat atom index) fills, with their weights.
    fn spread(&self, c: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let l = self.dict.len();
        let (p, a) = (c / l, c % l);
        let (start, v) = self.dict.atom(a);
        v.iter()
            .enumerate()
            .map(move |(i, g)| (p * self.dict.ks + start + i, *g))
    }
}

impl<T: Real, A: VoxelOperator<T> + ?Sized> LinearOperator<T> for Atoms<'_, T, A> {
    fn nrows(&self) -> usize {
        self.inner.nrows()
    }

    fn ncols(&self) -> usize {
        self.pixels * self.dict.len()
    }

    fn forward_kernel(&self, z: &[T], y: &mut [T], _: &mut [T]) {
        self.inner.apply(&self.voxels(z), y);
    }

    fn adjoint_kernel(&self, y: &[T], z: &mut [T], _: &mut [T]) {
        let mut u = vec![T::zero(); self.inner.ncols()];
        self.inner.apply_adjoint(y, &mut u);
        self.atoms_of(&u, z);
    }

    fn describe(&self) -> String {
        format!("Atoms({}, {} per bin)", self.inner.describe(), self.dict.q)
    }

    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        let n = self.ncols();
        if let Some(&bad) = columns.iter().find(|&&c| c >= n) {
            return Err(Error::IndexOutOfBounds {
                index: bad,
                len: n,
                context: "atoms",
            });
        }
        // The voxels the atoms fill, and the matrix from the atoms' amplitudes to them.
        let mut voxels: Vec<usize> = columns
            .iter()
            .flat_map(|&c| self.spread(c).map(|s| s.0))
            .collect();
        voxels.sort_unstable();
        voxels.dedup();
        let mut tri = sprs::TriMat::new((voxels.len(), columns.len()));
        for (j, &c) in columns.iter().enumerate() {
            for (v, g) in self.spread(c) {
                let i = voxels.binary_search(&v).expect("a listed voxel");
                tri.add_triplet(i, j, T::of_f64(g));
            }
        }
        let d = SparseMatrix::new(tri.to_csr())?;
        let a = self.inner.restrict_columns(voxels)?;
        Ok(Box::new(crate::operator::OperatorExt::compose(a, d)?))
    }

    fn space(&self) -> &dyn Space {
        self.inner.space()
    }
}

impl<T: Real, A: VoxelOperator<T> + ?Sized> VoxelOperator<T> for Atoms<'_, T, A> {
    fn column_len(&self) -> usize {
        self.dict.len()
    }

    fn columns_per_bin(&self) -> usize {
        self.dict.q
    }

    fn correlate(&self, r: &[T], z: &mut [T]) {
        let mut u = vec![T::zero(); self.inner.ncols()];
        self.inner.correlate(r, &mut u);
        self.atoms_of(&u, z);
    }

    fn self_correlations(&self, atoms: &[usize]) -> Vec<f64> {
        let (ks, l) = (self.dict.ks, self.dict.len());
        // The inner self-correlations of every voxel the atoms fill, then combined.
        let mut voxels: Vec<usize> = atoms
            .iter()
            .flat_map(|&c| self.spread(c).map(|s| s.0))
            .collect();
        voxels.sort_unstable();
        voxels.dedup();
        let rows = self.inner.self_correlations(&voxels);
        let mut out = Vec::with_capacity(atoms.len() * l);
        let mut col = vec![0.0f64; ks];
        for &c in atoms {
            col.iter_mut().for_each(|v| *v = 0.0);
            for (v, g) in self.spread(c) {
                let i = voxels.binary_search(&v).expect("a listed voxel");
                for (x, r) in col.iter_mut().zip(&rows[i * ks..(i + 1) * ks]) {
                    *x += g * r;
                }
            }
            out.extend((0..l).map(|a| self.dict.inner(a, &col)));
        }
        out
    }

    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        let (ks, l) = (self.dict.ks, self.dict.len());
        let g = self.inner.pixel_gram(pixel);
        // G·D, column by column, then Dᵀ(G·D).
        let mut gd = vec![0.0f64; ks * l];
        for a in 0..l {
            let (start, v) = self.dict.atom(a);
            for k in 0..ks {
                gd[k * l + a] = dot(v, &g[k * ks + start..k * ks + start + v.len()]);
            }
        }
        let mut out = vec![0.0f64; l * l];
        let mut col = vec![0.0f64; ks];
        for b in 0..l {
            for (k, c) in col.iter_mut().enumerate() {
                *c = gd[k * l + b];
            }
            for a in 0..l {
                out[a * l + b] = self.dict.inner(a, &col);
            }
        }
        out
    }

    fn uniform_pixel_gram(&self) -> bool {
        self.inner.uniform_pixel_gram()
    }

    /// ‖A·D e_c‖: where every pixel has the same Gram block G (±1 codes), √(hᵀGh) for atom
    /// c's values h, once per atom of the dictionary; otherwise from the atoms' columns.
    fn column_norms(&self, atoms: &[usize]) -> Vec<f64> {
        if !self.inner.uniform_pixel_gram() {
            return atoms
                .iter()
                .map(|&c| {
                    let (_, v) = self.column(c);
                    dot(&v, &v).sqrt()
                })
                .collect();
        }
        let ks = self.dict.ks;
        let g = self.inner.pixel_gram(0);
        let norms: Vec<f64> = (0..self.dict.len())
            .map(|a| {
                let (start, v) = self.dict.atom(a);
                let mut sq = 0.0;
                for (i, gi) in v.iter().enumerate() {
                    let row = &g[(start + i) * ks + start..(start + i) * ks + start + v.len()];
                    sq += gi * dot(v, row);
                }
                sq.max(0.0).sqrt()
            })
            .collect();
        atoms.iter().map(|&c| norms[c % self.dict.len()]).collect()
    }

    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        let parts: Vec<(usize, Vec<f64>, f64)> = self
            .spread(c)
            .map(|(v, g)| {
                let (s, col) = self.inner.column(v);
                (s, col, g)
            })
            .collect();
        let start = parts.iter().map(|p| p.0).min().unwrap_or(0);
        let end = parts.iter().map(|p| p.0 + p.1.len()).max().unwrap_or(0);
        let mut out = vec![0.0f64; end.saturating_sub(start)];
        for (s, col, g) in &parts {
            for (o, v) in out[s - start..].iter_mut().zip(col) {
                *o += g * v;
            }
        }
        (start, out)
    }

    fn structured_columns(&self) -> bool {
        self.inner.structured_columns()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::lidar::{Codes, Geometry, RdOperator};
    use crate::operator::pixel::{
        column_by_apply, column_norms_by_applies, pixel_gram_by_applies,
        self_correlations_by_applies,
    };
    use crate::operator::DotTest;

    fn close(a: &[f64], b: &[f64], what: &str) {
        assert_eq!(a.len(), b.len(), "{what}");
        let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= 1e-9 * scale, "{what} [{i}]: {x} vs {y}");
        }
    }

    #[test]
    fn the_atoms_structure_agrees_with_their_applications() {
        let g = Geometry::new(3, 4, 6).unwrap();
        let kp = 30;
        let pulse: Vec<f64> = (0..kp)
            .map(|i| ((i * 7 + 3) % 5 < 3) as u8 as f64)
            .collect();
        let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 5).unwrap());
        let op = RdOperator::new(g, pulse, codes).unwrap();
        for response in [Response::Triangle, Response::gaussian(0.8).unwrap()] {
            let dict = Dictionary::new(&response, g.ks, 4);
            assert_eq!(dict.len(), 21);
            let atoms = Atoms::new(&op, &dict).unwrap();
            assert!(DotTest::new().seed(3).measure(&atoms).passed());
            let picks = [0, 5, 21 + 13, 5 * 21 + 20, 11 * 21 + 7];
            close(
                &atoms.self_correlations(&picks),
                &self_correlations_by_applies(&atoms, &picks),
                "self-correlations",
            );
            close(
                &atoms.pixel_gram(4),
                &pixel_gram_by_applies(&atoms, 4),
                "gram",
            );
            close(
                &atoms.column_norms(&picks),
                &column_norms_by_applies(&atoms, &picks),
                "norms",
            );
            let (s, v) = atoms.column(picks[2]);
            let (s0, v0) = column_by_apply(&atoms, picks[2]);
            let mut a = vec![0.0; 80];
            let mut b = vec![0.0; 80];
            a[s..s + v.len()].copy_from_slice(&v);
            b[s0..s0 + v0.len()].copy_from_slice(&v0);
            close(&a, &b, "column");
            // The restriction to a few atoms applies their columns.
            let r = atoms.restrict_columns(picks.to_vec()).unwrap();
            let w = [1.0, -2.0, 0.5, 3.0, 0.25];
            let mut y1 = vec![0.0; atoms.nrows()];
            r.apply(&w, &mut y1);
            let mut z = vec![0.0; atoms.ncols()];
            for (c, v) in picks.iter().zip(w) {
                z[*c] += v;
            }
            let mut y2 = vec![0.0; atoms.nrows()];
            atoms.apply(&z, &mut y2);
            close(&y1, &y2, "restricted");
        }
    }
}
