//! Point clouds as binary PLY files (little-endian): one `vertex` element with float x, y, z
//! (metres), float intensity and the uint pixel row and column, read by the common point-cloud
//! tools (plyfile, Open3D, PCL, CloudCompare, MeshLab).

use std::path::Path;

use crate::error::Result;
use crate::lidar::PointCloud;

use super::{stage_bytes, StagedFile};

/// The bytes of a binary PLY file of `cloud`: x, y, z, intensity (written as float32), and each
/// point's pixel row and column.
///
/// # Panics
/// If `cloud.points` is not (P, 4) with P = `cloud.pixels.len()`, as
/// [`points`](crate::lidar::points) makes it.
pub fn ply_bytes(cloud: &PointCloud) -> Vec<u8> {
    let pixels = &cloud.pixels;
    assert_eq!(
        cloud.points.dim(),
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
    for (point, &(row, col)) in cloud.points.outer_iter().zip(pixels) {
        for v in point {
            bytes.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        bytes.extend_from_slice(&row.to_le_bytes());
        bytes.extend_from_slice(&col.to_le_bytes());
    }
    bytes
}

/// Stages the PLY file of `cloud` at `path` ([`stage_bytes`]).
///
/// # Errors
/// [`Error::File`](crate::Error::File) naming `path` when it cannot be written.
pub fn stage_points(path: impl AsRef<Path>, cloud: &PointCloud) -> Result<StagedFile> {
    stage_bytes(path, &ply_bytes(cloud))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_counts_the_points_and_each_point_takes_24_bytes() {
        let cloud = PointCloud {
            points: ndarray::arr2(&[[1.0, -2.0, 3.5, 0.25], [0.0, 0.0, 7.0, 1.0]]),
            pixels: vec![(0, 1), (4, 2)],
        };
        let bytes = ply_bytes(&cloud);
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
        let empty = PointCloud {
            points: ndarray::Array2::zeros((0, 4)),
            pixels: Vec::new(),
        };
        assert!(ply_bytes(&empty).ends_with(b"element vertex 0\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\nproperty uint row\nproperty uint col\nend_header\n"));
    }
}
