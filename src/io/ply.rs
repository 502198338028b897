//! Point clouds as binary PLY files (little-endian): one `vertex` element with float x, y, z
//! (metres), float intensity and the uint pixel row and column, read by the common point-cloud
//! tools (plyfile, Open3D, PCL, CloudCompare, MeshLab).

use std::path::Path;

use ndarray::Array2;

use crate::error::Result;

use super::{stage_bytes, StagedFile};

/// The bytes of a binary PLY file of the points `cloud` (P, 4): x, y, z, intensity, with each
/// point's pixel (row, column) from `pixels`. Values are written as float32.
///
/// # Panics
/// If `cloud` is not (P, 4) with P = `pixels.len()`: both come from
/// [`points`](crate::lidar::points).
pub fn ply_bytes(cloud: &Array2<f64>, pixels: &[(u32, u32)]) -> Vec<u8> {
    assert_eq!(
        cloud.dim(),
        (pixels.len(), 4),
        "one row of four values per pixel"
    );
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment rdlidar returns: x right, y down, z \
         forward, in metres; intensity = amplitude\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nproperty float intensity\nproperty uint row\n\
         property uint col\nend_header\n",
        pixels.len()
    );
    let mut bytes = Vec::with_capacity(header.len() + pixels.len() * 24);
    bytes.extend_from_slice(header.as_bytes());
    for (point, &(row, col)) in cloud.outer_iter().zip(pixels) {
        for v in point {
            bytes.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        bytes.extend_from_slice(&row.to_le_bytes());
        bytes.extend_from_slice(&col.to_le_bytes());
    }
    bytes
}

/// Stages the PLY file of `cloud` and `pixels` at `path` ([`stage_bytes`]).
///
/// # Errors
/// [`Error::File`](crate::Error::File) naming `path` when it cannot be written.
pub fn stage_points(
    path: impl AsRef<Path>,
    cloud: &Array2<f64>,
    pixels: &[(u32, u32)],
) -> Result<StagedFile> {
    stage_bytes(path, &ply_bytes(cloud, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_counts_the_points_and_each_point_takes_24_bytes() {
        let cloud = ndarray::arr2(&[[1.0, -2.0, 3.5, 0.25], [0.0, 0.0, 7.0, 1.0]]);
        let bytes = ply_bytes(&cloud, &[(0, 1), (4, 2)]);
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..at]).unwrap();
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(header.contains("element vertex 2\n"));
        let body = &bytes[at..];
        assert_eq!(body.len(), 2 * 24);
        let f = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
        let u = |o: usize| u32::from_le_bytes(body[o..o + 4].try_into().unwrap());
        assert_eq!(
            (f(0), f(4), f(8), f(12), u(16), u(20)),
            (1.0, -2.0, 3.5, 0.25, 0, 1)
        );
        assert_eq!((f(32), u(40), u(44)), (7.0, 4, 2));
        assert!(ply_bytes(&Array2::zeros((0, 4)), &[]).ends_with(b"element vertex 0\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\nproperty uint row\nproperty uint col\nend_header\n"));
    }
}
