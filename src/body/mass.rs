//! Exact mass properties of polyhedra.
//!
//! Each closed, outward-wound triangle mesh is split into signed tetrahedra
//! (origin, a, b, c); volume, first and second moments of a tetrahedron have
//! closed forms, and the signed sum is exact for any closed polyhedron (the
//! divergence theorem, as in Mirtich 1996 and Eberly's "Polyhedral Mass
//! Properties"). Moments about the origin are then shifted to the centre of
//! mass with the parallel-axis theorem.

use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};

/// Volume, centroid and unit-density inertia (about the centroid) of a body.
#[derive(Clone, Copy, Debug)]
pub struct MassProperties {
    pub volume: f64,
    pub centroid: Vector3<f64>,
    /// Inertia tensor about the centroid for density 1 (multiply by density).
    pub unit_inertia: Matrix3<f64>,
}

/// Accumulates moments over many closed triangle meshes (the convex parts of one body).
#[derive(Clone, Copy, Debug, Default)]
pub struct MomentSum {
    volume: f64,
    first: Vector3<f64>,
    /// ∫ x xᵀ dV about the origin.
    second: Matrix3<f64>,
}

impl MomentSum {
    pub fn new() -> Self {
        MomentSum {
            volume: 0.0,
            first: Vector3::zeros(),
            second: Matrix3::zeros(),
        }
    }

    /// Adds one closed, outward-wound triangle mesh.
    pub fn add_mesh(&mut self, vertices: &[Vector3<f64>], triangles: &[[usize; 3]]) {
        for t in triangles {
            let (a, b, c) = (vertices[t[0]], vertices[t[1]], vertices[t[2]]);
            // Signed volume of the tetrahedron (0, a, b, c).
            let v = a.dot(&b.cross(&c)) / 6.0;
            self.volume += v;
            // ∫ x dV over the tetrahedron = V (0 + a + b + c) / 4.
            self.first += v * (a + b + c) / 4.0;
            // ∫ x xᵀ dV = V/20 (Σ pᵢpᵢᵀ + (Σpᵢ)(Σpᵢ)ᵀ) with the origin as 4th vertex.
            let s = a + b + c;
            self.second += v / 20.0
                * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
        }
    }

    pub fn finish(&self) -> MassProperties {
        let volume = self.volume;
        let centroid = if volume != 0.0 {
            self.first / volume
        } else {
            Vector3::zeros()
        };
        // Covariance about the centroid, then I = tr(C) 1 − C.
        let cov = self.second - volume * centroid * centroid.transpose();
        let unit_inertia = Matrix3::identity() * cov.trace() - cov;
        MassProperties {
            volume,
            centroid,
            unit_inertia,
        }
    }
}

/// Principal frame of a symmetric inertia tensor: `I = R diag(m) Rᵀ` with R a
/// proper rotation (det +1), moments in ascending order.
pub fn principal_axes(inertia: &Matrix3<f64>) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let eig = SymmetricEigen::new(*inertia);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let mut axes = Matrix3::from_columns(&[
        eig.eigenvectors.column(order[0]).into_owned(),
        eig.eigenvectors.column(order[1]).into_owned(),
        eig.eigenvectors.column(order[2]).into_owned(),
    ]);
    if axes.determinant() < 0.0 {
        axes.set_column(2, &(-axes.column(2)));
    }
    let moments = Vector3::new(
        eig.eigenvalues[order[0]],
        eig.eigenvalues[order[1]],
        eig.eigenvalues[order[2]],
    );
    let rotation = UnitQuaternion::from_matrix(&axes);
    (rotation, moments)
}

/// Checks that an inertia tensor is symmetric, positive definite and physically
/// realisable (principal moments satisfy the triangle inequality).
pub fn check_inertia(inertia: &Matrix3<f64>) -> Result<(), String> {
    if inertia.iter().any(|x| !x.is_finite()) {
        return Err("is not finite".into());
    }
    let scale = inertia.abs().max();
    if (inertia - inertia.transpose()).abs().max() > 1e-9 * scale {
        return Err("is not symmetric".into());
    }
    let (_, m) = principal_axes(inertia);
    if m[0] <= 1e-12 * scale.max(f64::MIN_POSITIVE) || m[0] <= 0.0 {
        return Err(format!(
            "is not positive definite (principal moments {:.6e}, {:.6e}, {:.6e})",
            m[0], m[1], m[2]
        ));
    }
    if m[0] + m[1] < m[2] * (1.0 - 1e-9) {
        return Err(format!(
            "is not physically possible: principal moments {:.6e} + {:.6e} < {:.6e}",
            m[0], m[1], m[2]
        ));
    }
    Ok(())
}
