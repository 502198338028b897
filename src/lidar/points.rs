//! Returns as a point cloud: each return a point along its pixel's ray, at the range its depth
//! gives (d·c·τ/2 metres), with its amplitude as intensity.
//!
//! The camera is a pinhole at the origin looking along +z, with x to the right (the pixel
//! column growing) and y down (the pixel row growing), the frame of most camera software; the
//! optical axis passes through the centre of the M × N array. Pixel (i, j)'s ray is
//! (u, v, 1) with u = (j − (N − 1)/2)·p/f and v = (i − (M − 1)/2)·p/f, p/f the pixel pitch
//! over the focal length; a point at range r lies at r·(u, v, 1)/‖(u, v, 1)‖ (time of flight
//! measures the distance along the ray, not z).

use ndarray::Array2;

use crate::error::{Error, Result};

use super::returns::Returns;

/// How pixels map to rays: the tangent of the angle one pixel spans, across and down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// p/f across (per pixel column).
    pub across: f64,
    /// p/f down (per pixel row).
    pub down: f64,
}

impl Camera {
    /// A camera of pixel pitch `pitch` and focal length `focal` (any one unit for both).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`pixel_pitch`, `focal_length`) unless both are finite and
    /// > 0.
    pub fn pinhole(pitch: f64, focal: f64) -> Result<Camera> {
        positive("pixel_pitch", pitch)?;
        positive("focal_length", focal)?;
        let t = pitch / focal;
        if !t.is_finite() || t == 0.0 {
            return Err(Error::param(
                "pixel_pitch",
                format!("a pitch of {pitch} over a focal length of {focal} is no angle"),
            ));
        }
        Ok(Camera { across: t, down: t })
    }

    /// The camera whose `n` pixel columns span the horizontal field of view `horizontal` and
    /// whose `m` rows span `vertical` (both in degrees, the full angle edge to edge); square
    /// pixels when `vertical` is `None`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`fov`) unless the angles lie in (0°, 180°).
    pub fn field_of_view(
        horizontal: f64,
        vertical: Option<f64>,
        m: usize,
        n: usize,
    ) -> Result<Camera> {
        let tangent = |deg: f64| -> Result<f64> {
            if !(deg > 0.0 && deg < 180.0) {
                return Err(Error::param(
                    "fov",
                    format!("a field of view must lie between 0 and 180 degrees, got {deg}"),
                ));
            }
            Ok((deg.to_radians() / 2.0).tan())
        };
        let across = 2.0 * tangent(horizontal)? / n.max(1) as f64;
        let down = match vertical {
            Some(v) => 2.0 * tangent(v)? / m.max(1) as f64,
            None => across,
        };
        Ok(Camera { across, down })
    }

    /// The unit ray of pixel (`i`, `j`) of an `m` × `n` array.
    pub fn ray(&self, i: usize, j: usize, m: usize, n: usize) -> [f64; 3] {
        let u = (j as f64 - (n as f64 - 1.0) / 2.0) * self.across;
        let v = (i as f64 - (m as f64 - 1.0) / 2.0) * self.down;
        let norm = (u * u + v * v + 1.0).sqrt();
        [u / norm, v / norm, 1.0 / norm]
    }
}

fn positive(name: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            name,
            format!("must be finite and > 0, got {v}"),
        ))
    }
}

/// Returns as points ([`points`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud {
    /// (P, 4): x, y, z in metres and the intensity (the return's amplitude).
    pub points: Array2<f64>,
    /// Each point's pixel (row, column).
    pub pixels: Vec<(u32, u32)>,
}

/// Every return as a point: rows (x, y, z, intensity), x, y, z in metres along its pixel's ray
/// at range d·`bin_m`, intensity its amplitude; the pixel row and column of each point beside.
/// Pixels in row-major order, a pixel's returns nearest first.
///
/// # Errors
/// [`Error::InvalidParameter`] (`bin_m`) unless it is finite and > 0.
pub fn points(returns: &Returns, bin_m: f64, camera: &Camera) -> Result<PointCloud> {
    positive("bin_m", bin_m)?;
    let (layers, m, n) = returns.depth.dim();
    let mut rows = Vec::new();
    let mut pixels = Vec::new();
    for i in 0..m {
        for j in 0..n {
            let mut here: Vec<(f64, f64)> = (0..layers)
                .map(|r| (returns.depth[[r, i, j]], returns.amplitude[[r, i, j]]))
                .filter(|(d, _)| !d.is_nan())
                .collect();
            here.sort_by(|a, b| a.0.total_cmp(&b.0));
            let ray = camera.ray(i, j, m, n);
            for (d, a) in here {
                let r = d * bin_m;
                rows.extend([r * ray[0], r * ray[1], r * ray[2], a]);
                pixels.push((i as u32, j as u32));
            }
        }
    }
    let count = pixels.len();
    let points = Array2::from_shape_vec((count, 4), rows).expect("four values per point");
    Ok(PointCloud { points, pixels })
}

#[cfg(test)]
mod tests {
    use ndarray::arr3;

    use super::*;

    #[test]
    fn a_point_lies_on_its_pixels_ray_at_its_range() {
        let nan = f64::NAN;
        let returns = Returns::new(
            arr3(&[[[2.0, nan, 4.5]], [[nan, nan, 1.0]]]),
            arr3(&[[[0.5, 0.0, 2.0]], [[0.0, 0.0, 1.5]]]),
        )
        .unwrap();
        let camera = Camera::field_of_view(60.0, None, 1, 3).unwrap();
        let PointCloud {
            points: cloud,
            pixels,
        } = points(&returns, 0.03, &camera).unwrap();
        assert_eq!(cloud.dim(), (3, 4));
        assert_eq!(pixels, [(0, 0), (0, 2), (0, 2)]);
        // Pixel (0, 2)'s returns nearest first.
        assert_eq!(cloud[[1, 3]], 1.5);
        assert_eq!(cloud[[2, 3]], 2.0);
        for (row, range) in [(0, 0.06), (1, 0.03), (2, 0.135)] {
            let p = cloud.row(row);
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - range).abs() < 1e-15, "{r} vs {range}");
        }
        // The outer columns' rays make half the field of view less half a pixel with the axis:
        // the edge of the array is at 30°, the centre of the last column at atan(2/3·tan 30°).
        let p = cloud.row(1);
        let angle = (p[0] / p[2]).atan().to_degrees();
        let want = (2.0 / 3.0 * 30f64.to_radians().tan()).atan().to_degrees();
        assert!((angle - want).abs() < 1e-12, "{angle} vs {want}");
        assert!(p[1].abs() < 1e-15, "one row: on the horizontal plane");
        // A pinhole of pitch p and focal f is the field of view 2·atan(N·p/(2f)).
        let pinhole = Camera::pinhole(10e-6, 4e-3).unwrap();
        let fov = 2.0 * (3.0f64 * 10e-6 / (2.0 * 4e-3)).atan().to_degrees();
        let same = Camera::field_of_view(fov, None, 1, 3).unwrap();
        assert!((pinhole.across - same.across).abs() < 1e-15);
    }

    #[test]
    fn impossible_cameras_are_refused_by_name() {
        let name = |r: Result<Camera>| match r {
            Err(Error::InvalidParameter { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        assert_eq!(name(Camera::field_of_view(180.0, None, 4, 4)), "fov");
        assert_eq!(name(Camera::field_of_view(30.0, Some(0.0), 4, 4)), "fov");
        assert_eq!(name(Camera::pinhole(-1.0, 1.0)), "pixel_pitch");
        assert_eq!(name(Camera::pinhole(1.0, f64::INFINITY)), "focal_length");
        assert_eq!(name(Camera::pinhole(1e-300, 1e300)), "pixel_pitch");
    }
}
