//! KITTI OXTS packets: one line of 30 numbers per `oxts/data/*.txt` (the
//! OXTS RT3003 GPS/IMU, units as in the KITTI raw devkit's `dataformat.txt`).

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};

use super::KittiError;
use super::timestamps::read_text;

/// One packet is a ~500-byte line; 1 MiB leaves room for any padding yet
/// refuses a wrong file before it is read.
const MAX_OXTS_BYTES: u64 = 1 << 20;

const FIELD_COUNT: usize = 30;

/// Field names as in `dataformat.txt`, in file order, for error messages.
const FIELD_NAMES: [&str; FIELD_COUNT] = [
    "lat",
    "lon",
    "alt",
    "roll",
    "pitch",
    "yaw",
    "vn",
    "ve",
    "vf",
    "vl",
    "vu",
    "ax",
    "ay",
    "az",
    "af",
    "al",
    "au",
    "wx",
    "wy",
    "wz",
    "wf",
    "wl",
    "wu",
    "pos_accuracy",
    "vel_accuracy",
    "navstat",
    "numsats",
    "posmode",
    "velmode",
    "orimode",
];

/// Index of the first of the five integer fields (navstat .. orimode).
const FIRST_INTEGER_FIELD: usize = 25;

/// One OXTS packet. Angles: roll/pitch/yaw of the vehicle (IMU) frame in a
/// local east-north-up frame, yaw 0 = east, counter-clockwise positive.
/// `f/l/u` components are in the vehicle frame (forward, left, up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct OxtsPacket {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub yaw_rad: f64,
    pub vn_mps: f64,
    pub ve_mps: f64,
    pub vf_mps: f64,
    pub vl_mps: f64,
    pub vu_mps: f64,
    pub ax_mps2: f64,
    pub ay_mps2: f64,
    pub az_mps2: f64,
    pub af_mps2: f64,
    pub al_mps2: f64,
    pub au_mps2: f64,
    pub wx_radps: f64,
    pub wy_radps: f64,
    pub wz_radps: f64,
    pub wf_radps: f64,
    pub wl_radps: f64,
    pub wu_radps: f64,
    pub pos_accuracy_m: f64,
    pub vel_accuracy_mps: f64,
    pub navstat: i32,
    pub numsats: i32,
    pub posmode: i32,
    pub velmode: i32,
    pub orimode: i32,
}

impl OxtsPacket {
    /// Rotation from the vehicle frame to the local ENU frame:
    /// R = Rz(yaw) * Ry(pitch) * Rx(roll), as in pykitti's
    /// `rotz(yaw) @ roty(pitch) @ rotx(roll)` (nalgebra's Euler convention
    /// is the same: roll first, then pitch, then yaw, about fixed axes).
    pub fn orientation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(self.roll_rad, self.pitch_rad, self.yaw_rad)
    }

    /// Velocity in the vehicle frame (forward, left, up).
    pub fn velocity_vehicle_mps(&self) -> Vector3<f64> {
        Vector3::new(self.vf_mps, self.vl_mps, self.vu_mps)
    }

    /// Angular velocity in the vehicle frame (about forward, left, up).
    pub fn angular_velocity_vehicle_radps(&self) -> Vector3<f64> {
        Vector3::new(self.wf_radps, self.wl_radps, self.wu_radps)
    }

    /// Acceleration in the vehicle frame (forward, left, up); includes
    /// gravity, as an accelerometer measures it.
    pub fn acceleration_vehicle_mps2(&self) -> Vector3<f64> {
        Vector3::new(self.af_mps2, self.al_mps2, self.au_mps2)
    }
}

/// One packet from its line: exactly 30 finite numbers separated by
/// whitespace, the last five integral (written `4` or `4.0`).
pub(crate) fn parse_oxts_line(line: &str) -> Result<OxtsPacket, String> {
    let found = line.split_ascii_whitespace().count();
    if found != FIELD_COUNT {
        return Err(format!("expected {FIELD_COUNT} numbers, found {found}"));
    }
    let mut values = [0.0; FIELD_COUNT];
    for (index, (value, token)) in values
        .iter_mut()
        .zip(line.split_ascii_whitespace())
        .enumerate()
    {
        *value = parse_field(index, token)?;
    }
    // In KITTI's order (FIELD_NAMES).
    let v = values;
    let integer = |index: usize| integral(index, v[index]);
    Ok(OxtsPacket {
        lat_deg: v[0],
        lon_deg: v[1],
        alt_m: v[2],
        roll_rad: v[3],
        pitch_rad: v[4],
        yaw_rad: v[5],
        vn_mps: v[6],
        ve_mps: v[7],
        vf_mps: v[8],
        vl_mps: v[9],
        vu_mps: v[10],
        ax_mps2: v[11],
        ay_mps2: v[12],
        az_mps2: v[13],
        af_mps2: v[14],
        al_mps2: v[15],
        au_mps2: v[16],
        wx_radps: v[17],
        wy_radps: v[18],
        wz_radps: v[19],
        wf_radps: v[20],
        wl_radps: v[21],
        wu_radps: v[22],
        pos_accuracy_m: v[23],
        vel_accuracy_mps: v[24],
        navstat: integer(FIRST_INTEGER_FIELD)?,
        numsats: integer(FIRST_INTEGER_FIELD + 1)?,
        posmode: integer(FIRST_INTEGER_FIELD + 2)?,
        velmode: integer(FIRST_INTEGER_FIELD + 3)?,
        orimode: integer(FIRST_INTEGER_FIELD + 4)?,
    })
}

/// The packet of an `oxts/data/*.txt` file: its first non-empty line (later
/// lines are ignored, as pykitti does).
pub(crate) fn read_oxts_file(path: &Path) -> Result<OxtsPacket, KittiError> {
    let text = read_text(path, MAX_OXTS_BYTES, "OXTS packet file")?;
    let Some((index, line)) = text.lines().enumerate().find(|(_, l)| !l.trim().is_empty()) else {
        return Err(KittiError::Invalid {
            path: path.to_path_buf(),
            reason: "no OXTS packet (the file is empty)".into(),
        });
    };
    parse_oxts_line(line).map_err(|reason| KittiError::Malformed {
        path: path.to_path_buf(),
        line: index + 1,
        reason,
    })
}

/// Label of the field at a 0-based index, e.g. "field 7 (vn)".
fn field_label(index: usize) -> String {
    let name = FIELD_NAMES.get(index).copied().unwrap_or("?");
    format!("field {} ({name})", index + 1)
}

/// A finite number; NaN and infinities would poison every pose downstream.
fn parse_field(index: usize, token: &str) -> Result<f64, String> {
    let value: f64 = token
        .parse()
        .map_err(|_| format!("{}: not a number: '{token}'", field_label(index)))?;
    if !value.is_finite() {
        return Err(format!("{}: not finite: '{token}'", field_label(index)));
    }
    Ok(value)
}

/// An integral value that fits an i32 (status fields are written as floats
/// by some exporters, e.g. `4.0`).
fn integral(index: usize, value: f64) -> Result<i32, String> {
    let in_range = (f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&value);
    if value.fract() != 0.0 || !in_range {
        return Err(format!("{}: not an integer: {value}", field_label(index)));
    }
    // Exact: integral and within i32's range, checked above.
    Ok(value as i32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};
    use std::f64::consts::FRAC_PI_2;

    /// A packet from KITTI 2011_09_26 (as in its devkit examples).
    const KITTI_LINE: &str = "49.015003823272 8.4342971002335 116.43032836914 0.035752 0.00903 -1.1899336 -7.0720192757022 -6.3085508775767 9.4662183513123 -0.038188773542357 -0.039617221951797 -0.39601306451294 -0.34573937580246 9.6994228364313 -0.73283022105218 0.12466622289911 9.68946233393 -0.00079484658659012 0.0034123924770117 0.019166440099064 0.00025484658659012 0.0070123924770117 0.018666440099064 0.53812313079834 0.082307748451531 4 10 4 4 0";

    fn tokens() -> Vec<String> {
        KITTI_LINE.split(' ').map(str::to_string).collect()
    }

    fn with_field(index: usize, value: &str) -> String {
        let mut fields = tokens();
        fields[index] = value.to_string();
        fields.join(" ")
    }

    fn packet(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> OxtsPacket {
        OxtsPacket {
            roll_rad,
            pitch_rad,
            yaw_rad,
            ..parse_oxts_line(KITTI_LINE).expect("valid")
        }
    }

    #[test]
    fn parses_a_kitti_line() {
        let p = parse_oxts_line(KITTI_LINE).expect("valid");
        assert_eq!(p.lat_deg, 49.015003823272);
        assert_eq!(p.lon_deg, 8.4342971002335);
        assert_eq!(p.alt_m, 116.43032836914);
        assert_eq!(
            (p.roll_rad, p.pitch_rad, p.yaw_rad),
            (0.035752, 0.00903, -1.1899336)
        );
        assert_eq!((p.vn_mps, p.ve_mps), (-7.0720192757022, -6.3085508775767));
        assert_eq!(
            p.velocity_vehicle_mps(),
            Vector3::new(9.4662183513123, -0.038188773542357, -0.039617221951797)
        );
        assert_eq!(
            p.acceleration_vehicle_mps2(),
            Vector3::new(-0.73283022105218, 0.12466622289911, 9.68946233393)
        );
        assert_eq!(
            p.angular_velocity_vehicle_radps(),
            Vector3::new(0.00025484658659012, 0.0070123924770117, 0.018666440099064)
        );
        assert_eq!(
            (p.ax_mps2, p.az_mps2, p.wx_radps, p.wz_radps),
            (
                -0.39601306451294,
                9.6994228364313,
                -0.00079484658659012,
                0.019166440099064
            )
        );
        assert_eq!(
            (p.pos_accuracy_m, p.vel_accuracy_mps),
            (0.53812313079834, 0.082307748451531)
        );
        assert_eq!(
            (p.navstat, p.numsats, p.posmode, p.velmode, p.orimode),
            (4, 10, 4, 4, 0)
        );
    }

    #[test]
    fn tabs_and_float_written_integers_are_accepted() {
        let line = KITTI_LINE.replace(" 4 10 4 4 0", "\t4.0 10 4 4 -0.0\n");
        let p = parse_oxts_line(&line).expect("valid");
        assert_eq!((p.navstat, p.numsats, p.orimode), (4, 10, 0));
    }

    #[test]
    fn wrong_counts_are_refused() {
        let fields = tokens();
        let short = fields[..29].join(" ");
        assert_eq!(
            parse_oxts_line(&short).unwrap_err(),
            "expected 30 numbers, found 29"
        );
        let long = format!("{KITTI_LINE} 1");
        assert_eq!(
            parse_oxts_line(&long).unwrap_err(),
            "expected 30 numbers, found 31"
        );
        assert_eq!(
            parse_oxts_line("").unwrap_err(),
            "expected 30 numbers, found 0"
        );
    }

    #[test]
    fn bad_values_name_their_field() {
        assert_eq!(
            parse_oxts_line(&with_field(6, "abc")).unwrap_err(),
            "field 7 (vn): not a number: 'abc'"
        );
        assert_eq!(
            parse_oxts_line(&with_field(0, "NaN")).unwrap_err(),
            "field 1 (lat): not finite: 'NaN'"
        );
        assert!(parse_oxts_line(&with_field(2, "inf")).is_err());
        assert!(parse_oxts_line(&with_field(29, "1e400")).is_err());
        assert_eq!(
            parse_oxts_line(&with_field(25, "4.5")).unwrap_err(),
            "field 26 (navstat): not an integer: 4.5"
        );
        assert!(parse_oxts_line(&with_field(26, "3e10")).is_err());
    }

    #[test]
    fn field_labels() {
        assert_eq!(field_label(0), "field 1 (lat)");
        assert_eq!(field_label(29), "field 30 (orimode)");
        assert_eq!(field_label(30), "field 31 (?)");
    }

    #[test]
    fn integral_checks_range_and_fraction() {
        assert_eq!(integral(25, 4.0), Ok(4));
        assert_eq!(integral(25, -2.0), Ok(-2));
        assert!(integral(25, 0.5).is_err());
        assert!(integral(25, 2.0 * f64::from(i32::MAX)).is_err());
    }

    #[test]
    fn yaw_quarter_turn_points_forward_north() {
        // Yaw 0 is east (x of ENU); a quarter turn counter-clockwise is north.
        let forward = packet(0.0, 0.0, FRAC_PI_2).orientation() * Vector3::x();
        assert!((forward - Vector3::y()).norm() < 1e-12, "{forward}");
    }

    #[test]
    fn orientation_is_rz_ry_rx() {
        let (roll, pitch, yaw) = (0.3, -0.2, 1.1);
        let expected = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), pitch)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), roll);
        let got = packet(roll, pitch, yaw).orientation().to_rotation_matrix();
        assert!((got.matrix() - expected.matrix()).abs().max() < 1e-12);
        // The other order differs, so the check above has teeth.
        let reversed = Rotation3::from_axis_angle(&Vector3::x_axis(), roll)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), pitch)
            * Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
        assert!((got.matrix() - reversed.matrix()).abs().max() > 0.01);
    }

    #[test]
    fn pitch_and_roll_signs_match_dataformat() {
        // dataformat.txt: pitch positive = front down, roll positive = left
        // side up. Positive pitch about the left (y) axis sends x to -z.
        let forward = packet(0.0, FRAC_PI_2, 0.0).orientation() * Vector3::x();
        assert!((forward + Vector3::z()).norm() < 1e-12, "{forward}");
        // Positive roll about forward (x) lifts the left side: y to z.
        let left = packet(FRAC_PI_2, 0.0, 0.0).orientation() * Vector3::y();
        assert!((left - Vector3::z()).norm() < 1e-12, "{left}");
    }

    #[test]
    fn reads_the_first_non_empty_line() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("0000000000.txt");
        std::fs::write(&path, format!("\n{KITTI_LINE}\n")).expect("write");
        assert_eq!(read_oxts_file(&path).expect("valid").numsats, 10);
        std::fs::write(&path, format!("\n\n{}\n", with_field(3, "x"))).expect("write");
        match read_oxts_file(&path) {
            Err(KittiError::Malformed {
                line: 3, reason, ..
            }) => {
                assert_eq!(reason, "field 4 (roll): not a number: 'x'")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn file_errors() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("0000000000.txt");
        assert!(matches!(
            read_oxts_file(&path),
            Err(KittiError::Missing { .. })
        ));
        std::fs::write(&path, " \n\n").expect("write");
        assert!(matches!(
            read_oxts_file(&path),
            Err(KittiError::Invalid { .. })
        ));
        let file = std::fs::File::create(&path).expect("create");
        file.set_len(MAX_OXTS_BYTES + 1).expect("set_len");
        assert!(matches!(
            read_oxts_file(&path),
            Err(KittiError::Invalid { .. })
        ));
    }
}
