//! KITTI `calib_imu_to_velo.txt`: the rigid transform taking IMU (OXTS)
//! coordinates to Velodyne coordinates, `p_velo = R * p_imu + T`.

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

use super::KittiError;
use super::timestamps::read_text;

/// The file is three short lines; 1 MiB refuses a wrong file unread.
const MAX_CALIB_BYTES: u64 = 1 << 20;

/// How far `R` may be from orthonormal (largest entry of `RᵀR - I`): KITTI
/// prints 7 significant digits, so its matrices are off by ~1e-6; 1e-3 still
/// refuses a transposed or scaled matrix.
const MAX_ORTHONORMAL_ERROR: f64 = 1e-3;

/// `velo_from_imu`: maps a point in the IMU frame to the Velodyne frame.
/// Only the `R:` (9 numbers, row-major) and `T:` (3 numbers, metres) lines
/// matter; other lines (`calib_time: ...`) are ignored. Errors carry the
/// 1-based line, or 0 when a key is missing altogether.
pub(crate) fn parse_imu_to_velo(text: &str) -> Result<Isometry3<f64>, (usize, String)> {
    let mut rotation_rows: Option<(usize, [f64; 9])> = None;
    let mut translation_m: Option<(usize, [f64; 3])> = None;
    for (index, line) in text.lines().enumerate() {
        let line_number = index + 1;
        let Some((key, values)) = line.split_once(':') else {
            continue;
        };
        let fail = |reason| (line_number, reason);
        match key.trim() {
            "R" => set_once(&mut rotation_rows, line_number, "R", parse_numbers(values))
                .map_err(fail)?,
            "T" => set_once(&mut translation_m, line_number, "T", parse_numbers(values))
                .map_err(fail)?,
            _ => {}
        }
    }
    let (rotation_line, rows) = rotation_rows.ok_or((0, "no 'R:' line".to_string()))?;
    let (_, [tx_m, ty_m, tz_m]) = translation_m.ok_or((0, "no 'T:' line".to_string()))?;
    let rotation = rotation_from_rows(&rows).map_err(|reason| (rotation_line, reason))?;
    Ok(Isometry3::from_parts(
        Translation3::new(tx_m, ty_m, tz_m),
        rotation,
    ))
}

/// The calibration of a drive's date folder (`2011_09_26/calib_imu_to_velo.txt`).
pub(crate) fn read_imu_to_velo(path: &Path) -> Result<Isometry3<f64>, KittiError> {
    let text = read_text(path, MAX_CALIB_BYTES, "IMU-to-Velodyne calibration")?;
    parse_imu_to_velo(&text).map_err(|(line, reason)| match line {
        0 => KittiError::Invalid {
            path: path.to_path_buf(),
            reason,
        },
        line => KittiError::Malformed {
            path: path.to_path_buf(),
            line,
            reason,
        },
    })
}

/// Store a key's value, refusing a second occurrence: which one would win
/// is a guess, and a guessed calibration silently skews every point.
fn set_once<const N: usize>(
    slot: &mut Option<(usize, [f64; N])>,
    line_number: usize,
    key: &str,
    parsed: Result<[f64; N], String>,
) -> Result<(), String> {
    if let Some((first_line, _)) = slot {
        return Err(format!("second '{key}:' line (first on line {first_line})"));
    }
    let values = parsed.map_err(|reason| format!("{key}: {reason}"))?;
    *slot = Some((line_number, values));
    Ok(())
}

/// Exactly `N` finite numbers separated by whitespace.
fn parse_numbers<const N: usize>(text: &str) -> Result<[f64; N], String> {
    let found = text.split_ascii_whitespace().count();
    if found != N {
        return Err(format!("expected {N} numbers, found {found}"));
    }
    let mut values = [0.0; N];
    for (value, token) in values.iter_mut().zip(text.split_ascii_whitespace()) {
        *value = token
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| format!("not a finite number: '{token}'"))?;
    }
    Ok(values)
}

/// The rotation of a row-major 3x3 matrix that must already be one, up to
/// print rounding; the result is re-orthonormalised so that composing many
/// poses does not accumulate the rounding.
fn rotation_from_rows(rows: &[f64; 9]) -> Result<UnitQuaternion<f64>, String> {
    let matrix = Matrix3::from_row_slice(rows);
    let error = (matrix.transpose() * matrix - Matrix3::identity())
        .abs()
        .max();
    if error > MAX_ORTHONORMAL_ERROR {
        return Err(format!(
            "R is not orthonormal (|RᵀR - I| up to {error:.2e}, limit {MAX_ORTHONORMAL_ERROR:.0e})"
        ));
    }
    let determinant = matrix.determinant();
    if determinant <= 0.0 {
        return Err(format!(
            "R is a reflection, not a rotation (det {determinant:.3})"
        ));
    }
    // A direct conversion gives a close first guess (normalised: from a
    // not-quite-rotation it is not quite unit); the iteration then finds the
    // nearest rotation, bounded so no input can make it spin. The final
    // normalisation removes what the matrix-to-quaternion step rounds.
    let direct = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(matrix));
    let guess = UnitQuaternion::new_normalize(direct.into_inner());
    let nearest = UnitQuaternion::from_matrix_eps(&matrix, f64::EPSILON, 100, guess);
    Ok(UnitQuaternion::new_normalize(nearest.into_inner()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    /// KITTI raw 2011_09_26 `calib_imu_to_velo.txt`.
    const KITTI_CALIB: &str = "calib_time: 25-May-2012 14:44:40
R: 9.999976e-01 7.553071e-04 -2.035826e-03 -7.854027e-04 9.998898e-01 -1.482298e-02 2.024406e-03 1.482454e-02 9.998881e-01
T: -8.086759e-01 3.195559e-01 -7.997231e-01
";

    const R_ROWS: [f64; 9] = [
        9.999976e-01,
        7.553071e-04,
        -2.035826e-03,
        -7.854027e-04,
        9.998898e-01,
        -1.482298e-02,
        2.024406e-03,
        1.482454e-02,
        9.998881e-01,
    ];

    #[test]
    fn kitti_calibration_maps_r_p_plus_t() {
        let velo_from_imu = parse_imu_to_velo(KITTI_CALIB).expect("valid");
        let p_imu = Point3::new(1.0, -2.0, 3.0);
        let expected = Matrix3::from_row_slice(&R_ROWS) * p_imu.coords
            + Vector3::new(-8.086759e-01, 3.195559e-01, -7.997231e-01);
        let got = velo_from_imu * p_imu;
        assert!((got.coords - expected).norm() < 1e-5, "{got} vs {expected}");
        // The IMU origin lands at T.
        let origin = velo_from_imu * Point3::origin();
        assert!(
            (origin.coords - Vector3::new(-8.086759e-01, 3.195559e-01, -7.997231e-01)).norm()
                < 1e-12
        );
    }

    #[test]
    fn rotation_is_exactly_orthonormal() {
        let rotation = rotation_from_rows(&R_ROWS).expect("rotation");
        let m = rotation.to_rotation_matrix().into_inner();
        assert!((m.transpose() * m - Matrix3::identity()).abs().max() < 1e-14);
        assert!((m - Matrix3::from_row_slice(&R_ROWS)).abs().max() < 1e-5);
    }

    #[test]
    fn large_rotations_are_recovered() {
        // A half turn about z: far from the identity, where a poor first
        // guess would matter.
        let rows = [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0];
        let rotation = rotation_from_rows(&rows).expect("rotation");
        let x = rotation * Vector3::x();
        assert!((x + Vector3::x()).norm() < 1e-12, "{x}");
    }

    #[test]
    fn non_rotations_are_refused() {
        let scaled = R_ROWS.map(|v| 2.0 * v);
        assert!(
            rotation_from_rows(&scaled)
                .unwrap_err()
                .contains("orthonormal")
        );
        let reflection = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0];
        assert!(
            rotation_from_rows(&reflection)
                .unwrap_err()
                .contains("reflection")
        );
        let text = KITTI_CALIB.replace("9.999976e-01 7.553071e-04", "9.999976e-01 7.553071e-02");
        assert_eq!(parse_imu_to_velo(&text).unwrap_err().0, 2);
    }

    #[test]
    fn missing_keys_are_line_0() {
        let no_t: String = KITTI_CALIB.lines().take(2).collect::<Vec<_>>().join("\n");
        let (line, reason) = parse_imu_to_velo(&no_t).unwrap_err();
        assert_eq!((line, reason.as_str()), (0, "no 'T:' line"));
        let no_r = KITTI_CALIB.replace("R:", "Q:");
        assert_eq!(
            parse_imu_to_velo(&no_r).unwrap_err(),
            (0, "no 'R:' line".to_string())
        );
        assert_eq!(parse_imu_to_velo("").unwrap_err().0, 0);
    }

    #[test]
    fn wrong_counts_and_values_name_the_line() {
        let eight = KITTI_CALIB.replace(" 9.998881e-01\n", "\n");
        let (line, reason) = parse_imu_to_velo(&eight).unwrap_err();
        assert_eq!(
            (line, reason.as_str()),
            (2, "R: expected 9 numbers, found 8")
        );
        let bad_t = KITTI_CALIB.replace("T: -8.086759e-01", "T: nan");
        let (line, reason) = parse_imu_to_velo(&bad_t).unwrap_err();
        assert_eq!(
            (line, reason.as_str()),
            (3, "T: not a finite number: 'nan'")
        );
        let twice = format!("{KITTI_CALIB}T: 0 0 0\n");
        assert_eq!(parse_imu_to_velo(&twice).unwrap_err().0, 4);
    }

    #[test]
    fn other_lines_are_ignored() {
        let text = format!("junk without colon\ndelta_f: 1 2\n\n{KITTI_CALIB}");
        assert!(parse_imu_to_velo(&text).is_ok());
    }

    #[test]
    fn parse_numbers_counts_and_checks() {
        assert_eq!(parse_numbers::<2>(" 1 -2.5e1 "), Ok([1.0, -25.0]));
        assert!(parse_numbers::<2>("1").is_err());
        assert!(parse_numbers::<2>("1 x").is_err());
        assert!(parse_numbers::<1>("inf").is_err());
    }

    #[test]
    fn reads_files() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("calib_imu_to_velo.txt");
        assert!(matches!(
            read_imu_to_velo(&path),
            Err(KittiError::Missing { .. })
        ));
        std::fs::write(&path, KITTI_CALIB).expect("write");
        assert!(read_imu_to_velo(&path).is_ok());
        std::fs::write(&path, "calib_time: x\nR: 1 0 0 0 1 0 0 0 1\n").expect("write");
        assert!(matches!(
            read_imu_to_velo(&path),
            Err(KittiError::Invalid { .. })
        ));
        std::fs::write(&path, "R: 1 0 0\nT: 0 0 0\n").expect("write");
        assert!(matches!(
            read_imu_to_velo(&path),
            Err(KittiError::Malformed { line: 1, .. })
        ));
        let file = std::fs::File::create(&path).expect("create");
        file.set_len(MAX_CALIB_BYTES + 1).expect("set_len");
        assert!(matches!(
            read_imu_to_velo(&path),
            Err(KittiError::Invalid { .. })
        ));
    }
}
