use nalgebra::{Matrix4, Point3, Vector3};

use super::RenderError;

/// A perspective pin-hole camera in a right-handed, z-up world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    /// World up; `[0, 0, 1]` by default. If it is parallel to the line of
    /// sight (looking straight down), the world y axis stands in for it.
    pub up: [f32; 3],
    /// Vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera::looking_at([3.0, -4.0, 2.5], [0.0, 0.0, 0.0])
    }
}

impl Camera {
    /// z up, 45° vertical field of view.
    pub fn looking_at(eye: [f32; 3], target: [f32; 3]) -> Camera {
        Camera {
            eye,
            target,
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 45.0,
        }
    }

    pub(crate) fn basis(&self) -> Result<Basis, RenderError> {
        let eye = Vector3::from(self.eye);
        let target = Vector3::from(self.target);
        let up = Vector3::from(self.up);
        if !(eye.iter().chain(target.iter()).chain(up.iter())).all(|v| v.is_finite()) {
            return Err(RenderError::BadCamera(format!(
                "non-finite value in {self:?}"
            )));
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(RenderError::BadCamera(format!(
                "fov_y_deg = {} is outside (0, 180)",
                self.fov_y_deg
            )));
        }
        let forward = (target - eye)
            .try_normalize(1e-12)
            .ok_or_else(|| RenderError::BadCamera("eye and target coincide".into()))?;
        let up = up.try_normalize(1e-12).unwrap_or(Vector3::z());
        // sin of the angle between up and the line of sight; below ~0.1°
        // look_at's cross products lose all precision.
        let up = if forward.cross(&up).norm() > 2e-3 {
            up
        } else if forward.cross(&Vector3::y()).norm() > 2e-3 {
            Vector3::y()
        } else {
            Vector3::x()
        };
        let right = forward.cross(&up).normalize();
        Ok(Basis {
            eye,
            target,
            up,
            forward,
            right,
        })
    }
}

pub(crate) struct Basis {
    pub eye: Vector3<f32>,
    pub target: Vector3<f32>,
    /// Never parallel to `forward`.
    pub up: Vector3<f32>,
    pub forward: Vector3<f32>,
    pub right: Vector3<f32>,
}

impl Basis {
    /// View-projection for wgpu's clip space (x, y in [-1, 1], z in [0, 1])
    /// with reversed Z: near maps to depth 1 and far to 0, so the float depth
    /// buffer's dense values near 0 meet the 1/z compression and precision is
    /// roughly uniform over the range; compare with `Greater`, clear with 0.
    ///
    /// With f = 1/tan(fov/2), a view-space point (x, y, z) (the camera looks
    /// down -z) goes to clip (f x / aspect, f y, n (z + far) / (far - n), -z),
    /// so depth = n (z + far) / ((far - n)(-z)): 1 at z = -n, 0 at z = -far.
    pub fn view_projection(
        &self,
        fov_y_deg: f32,
        aspect: f32,
        near: f32,
        far: f32,
    ) -> Matrix4<f32> {
        let view = Matrix4::look_at_rh(
            &Point3::from(self.eye),
            &Point3::from(self.target),
            &self.up,
        );
        let f = 1.0 / (fov_y_deg.to_radians() * 0.5).tan();
        let (n, fa) = (near, far);
        #[rustfmt::skip]
        let proj = Matrix4::new(
            f / aspect, 0.0, 0.0, 0.0,
            0.0, f, 0.0, 0.0,
            0.0, 0.0, n / (fa - n), n * fa / (fa - n),
            0.0, 0.0, -1.0, 0.0,
        );
        proj * view
    }

    /// Direction towards the key light: above the scene, from the viewer's
    /// side and a little to the left, so the three faces of a box seen from a
    /// 3/4 view get three different tones (≈ 0.82, 0.55, 0.15 of full light
    /// for a box whose faces are at 45° to the view).
    pub fn key_light(&self) -> Vector3<f32> {
        let world_up = self.up;
        let ahead = self.forward - world_up * self.forward.dot(&world_up);
        let ahead = ahead
            .try_normalize(1e-6)
            .unwrap_or_else(|| self.right.cross(&world_up));
        (world_up - ahead * 0.6 - self.right * 0.35).normalize()
    }
}

/// A camera that frames `points` from a 3/4 view: from the front (-y), to
/// the right (+x) and above (+z, about 30° elevation), aimed at the centre of
/// their bounding box and just far enough back that every point lies inside
/// the vertical field of view with a 10 % margin (the horizontal one is
/// wider for landscape frames). Pass body-box corners or mesh vertices, not
/// just body centres (see [`super::Renderer::look_at_instances`]). An empty
/// slice gives [`Camera::default`].
pub fn look_at_scene(points: &[[f32; 3]]) -> Camera {
    let finite: Vec<Vector3<f32>> = points
        .iter()
        .map(|p| Vector3::from(*p))
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let Some(first) = finite.first() else {
        return Camera::default();
    };
    let (lo, hi) = finite
        .iter()
        .fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let centre = (lo + hi) * 0.5;
    let fov_y_deg: f32 = 45.0;
    let back = Vector3::new(0.55, -1.0, 0.65).normalize();
    let forward = -back;
    let right = forward.cross(&Vector3::z()).normalize();
    let up = right.cross(&forward);
    // A point p (relative to the centre) seen from eye = centre + back * d
    // is at depth d + p·forward and off-axis by p·right and p·up; it is in
    // frame when both offsets are at most tan(fov/2) times its depth, so d
    // must be at least max(|p·right|, |p·up|) / tan(fov/2) - p·forward.
    let tan_half = (fov_y_deg.to_radians() * 0.5).tan() / 1.1;
    let distance = finite
        .iter()
        .map(|p| {
            let p = p - centre;
            p.dot(&right).abs().max(p.dot(&up).abs()) / tan_half - p.dot(&forward)
        })
        .fold(0.0f32, f32::max);
    // Stay outside the box's bounding sphere (a flat scene seen edge-on
    // would otherwise put the eye among the bodies), and a single point
    // still needs somewhere to stand back to.
    let distance = distance.max((hi - lo).norm() * 0.55).max(1.0);
    Camera {
        eye: (centre + back * distance).into(),
        target: centre.into(),
        up: [0.0, 0.0, 1.0],
        fov_y_deg,
    }
}
