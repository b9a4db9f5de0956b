//! Tests of `mpc_sim::plot`: CSV round trip, PNG figures, empty input.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use mpc_sim::log::Sample;
use mpc_sim::plot::{HEIGHT, PlotError, WIDTH, write_csv, write_plots};

/// The `Sample` field names in declaration order (kept by hand, so that a change of the
/// log's columns is noticed here).
const FIELDS: [&str; 34] = [
    "t",
    "phase",
    "failsafe",
    "pose_valid",
    "x",
    "y",
    "z",
    "x_ref",
    "y_ref",
    "z_ref",
    "vx",
    "vy",
    "vz",
    "qw",
    "qx",
    "qy",
    "qz",
    "pitch_turned",
    "wx",
    "wy",
    "wz",
    "wx_cmd",
    "wy_cmd",
    "wz_cmd",
    "wy_ref",
    "thrust_cmd",
    "thrust",
    "f1",
    "f2",
    "f3",
    "f4",
    "solver_us",
    "qp_iterations",
    "fallback",
];

/// A fresh, unique directory under the system temp dir.
fn temp_dir(tag: &str) -> PathBuf {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let dir =
        std::env::temp_dir().join(format!("mpc-sim-plot-{tag}-{}-{nanos}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Removes `dir` unless `MPC_SIM_KEEP_PLOTS` is set (then prints where it is).
fn cleanup(dir: &Path) {
    if std::env::var_os("MPC_SIM_KEEP_PLOTS").is_some() {
        eprintln!("kept {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// A synthetic run: `n` samples at 200 Hz, four phases, a pitch flip in phase 2, the outer
/// loop running every 10th step.
fn trajectory(n: usize) -> Vec<Sample> {
    (0..n)
        .map(|i| {
            let t = i as f64 * 0.005;
            let phase = match t {
                t if t < 2.0 => 0,
                t if t < 5.0 => 1,
                t if t < 6.0 => 2,
                _ => 3,
            };
            let outer = i % 10 == 0;
            let flip = phase == 2;
            let wy_ref = if flip { 5.0 * PI } else { 0.0 };
            Sample {
                t,
                phase,
                failsafe: false,
                pose_valid: i % 97 != 0,
                x: (0.5 * t).sin() + 0.02 * (7.0 * t).sin(),
                y: 0.5 * (0.3 * t).cos(),
                z: 1.0 + 0.2 * (0.8 * t).sin(),
                x_ref: (0.5 * t).sin(),
                y_ref: 0.5 * (0.3 * t).cos() + 0.05,
                z_ref: 1.0 + 0.2 * (0.8 * t).sin() - 0.03,
                vx: 0.5 * (0.5 * t).cos(),
                vy: -0.15 * (0.3 * t).sin(),
                vz: 0.16 * (0.8 * t).cos(),
                qw: 1.0,
                qx: 0.0,
                qy: 0.0,
                qz: 0.0,
                pitch_turned: if flip { (t - 5.0) * 5.0 * PI } else { 0.0 },
                wx: 0.3 * (3.0 * t).sin(),
                wy: if flip {
                    5.0 * PI * (1.0 - (-(t - 5.0) * 20.0).exp())
                } else {
                    0.1 * (2.0 * t).sin()
                },
                wz: 0.05 * (1.5 * t).cos(),
                wx_cmd: 0.3 * (3.0 * t + 0.2).sin(),
                wy_cmd: if flip {
                    5.0 * PI
                } else {
                    0.1 * (2.0 * t + 0.2).sin()
                },
                wz_cmd: 0.05 * (1.5 * t + 0.2).cos(),
                wy_ref,
                thrust_cmd: 9.81 + (t * 1.3).sin(),
                thrust: 9.81 + (t * 1.3 - 0.1).sin(),
                f1: 2.45 + 0.3 * (t * 1.1).sin(),
                f2: 2.45 + 0.3 * (t * 1.2).sin(),
                f3: 2.45 + 0.3 * (t * 1.3).sin(),
                f4: 2.45 + 0.3 * (t * 1.4).sin(),
                solver_us: if outer {
                    300.0 + 80.0 * (t * 3.0).sin().abs()
                } else {
                    f64::NAN
                },
                qp_iterations: if outer {
                    (5.0 + 4.0 * (t * 0.7).sin()).round()
                } else {
                    f64::NAN
                },
                fallback: i % 500 == 0,
            }
        })
        .collect()
}

/// Every column of a sample as f64 (bools as 0/1), in field order.
fn columns(s: &Sample) -> [f64; 34] {
    [
        s.t,
        f64::from(s.phase),
        f64::from(u8::from(s.failsafe)),
        f64::from(u8::from(s.pose_valid)),
        s.x,
        s.y,
        s.z,
        s.x_ref,
        s.y_ref,
        s.z_ref,
        s.vx,
        s.vy,
        s.vz,
        s.qw,
        s.qx,
        s.qy,
        s.qz,
        s.pitch_turned,
        s.wx,
        s.wy,
        s.wz,
        s.wx_cmd,
        s.wy_cmd,
        s.wz_cmd,
        s.wy_ref,
        s.thrust_cmd,
        s.thrust,
        s.f1,
        s.f2,
        s.f3,
        s.f4,
        s.solver_us,
        s.qp_iterations,
        f64::from(u8::from(s.fallback)),
    ]
}

fn parse_cell(field: &str, cell: &str) -> f64 {
    match cell {
        "" => f64::NAN,
        "true" => 1.0,
        "false" => 0.0,
        c => c
            .parse()
            .unwrap_or_else(|e| panic!("column {field}: cannot parse {c:?}: {e}")),
    }
}

#[test]
fn csv_round_trips_with_header_and_empty_nan_cells() {
    let dir = temp_dir("csv");
    // Nested, not yet existing directory: write_csv creates it.
    let path = dir.join("sub").join("log.csv");
    let mut samples = trajectory(7);
    samples[3].failsafe = true;
    samples[4].x = -1.25e-7;
    samples[5].f3 = f64::INFINITY;
    write_csv(&path, &samples).unwrap();

    let text = std::fs::read_to_string(&path).unwrap();
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(text.as_bytes());
    let header: Vec<String> = rdr.headers().unwrap().iter().map(str::to_string).collect();
    assert_eq!(header, FIELDS);

    let rows: Vec<csv::StringRecord> = rdr.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), samples.len());
    let mut empty_cells = 0;
    for (row, s) in rows.iter().zip(&samples) {
        assert_eq!(row.len(), FIELDS.len());
        for ((field, cell), want) in FIELDS.iter().zip(row.iter()).zip(columns(s)) {
            assert_ne!(cell, "NaN", "NaN must be written as an empty cell");
            let got = parse_cell(field, cell);
            if want.is_nan() {
                assert_eq!(cell, "", "column {field}: NaN not written as an empty cell");
                empty_cells += 1;
            } else {
                assert_eq!(got, want, "column {field}: {cell:?} does not round-trip");
            }
        }
    }
    // Rows 1..=6 have no outer step: solver_us and qp_iterations are NaN there.
    assert_eq!(empty_cells, 12);
    assert!(text.contains("true"), "failsafe flag written as a bool");
    cleanup(&dir);
}

#[test]
fn csv_of_empty_log_has_only_the_header() {
    let dir = temp_dir("csv-empty");
    let path = dir.join("empty.csv");
    write_csv(&path, &[]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.trim_end(), FIELDS.join(","));
    cleanup(&dir);
}

#[test]
fn csv_to_unwritable_path_is_an_error_naming_the_path() {
    let dir = temp_dir("csv-bad");
    let blocker = dir.join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let path = blocker.join("log.csv");
    let err = write_csv(&path, &trajectory(3)).unwrap_err();
    assert!(
        err.to_string().contains(&*blocker.to_string_lossy()),
        "{err}"
    );
    cleanup(&dir);
}

/// Width and height from a PNG's IHDR chunk, after checking the signature.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert!(bytes.len() > 33, "PNG too short: {} bytes", bytes.len());
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[8..12], &13u32.to_be_bytes(), "IHDR length");
    assert_eq!(&bytes[12..16], b"IHDR", "first chunk is IHDR");
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    (be(&bytes[16..20]), be(&bytes[20..24]))
}

/// Size of a blank white PNG of the figure size, encoded the same way.
fn blank_png_len(dir: &Path) -> usize {
    let path = dir.join("blank.png");
    let white = vec![255u8; WIDTH as usize * HEIGHT as usize * 3];
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut enc = png::Encoder::new(file, WIDTH, HEIGHT);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().unwrap();
    w.write_image_data(&white).unwrap();
    w.finish().unwrap();
    std::fs::read(&path).unwrap().len()
}

/// Decodes a PNG and returns the share of pixels that are not white, and whether some are
/// red-dominant and some blue-dominant (the reference and the true curves).
fn ink(bytes: &[u8]) -> (f64, bool, bool) {
    let dec = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let px: Vec<&[u8]> = buf[..info.buffer_size()].chunks(3).collect();
    let inked = px.iter().filter(|p| p.iter().any(|&c| c < 250)).count();
    let red = px.iter().any(|p| p[0] > 150 && p[1] < 100 && p[2] < 100);
    let blue = px.iter().any(|p| p[2] > 150 && p[0] < 100);
    (inked as f64 / px.len() as f64, red, blue)
}

#[test]
fn plots_are_written_as_non_blank_pngs() {
    let dir = temp_dir("png");
    let out = dir.join("figs"); // not yet existing
    let samples = trajectory(2000);
    let names = ["takeoff", "hover", "flip", "recover"];
    let set = write_plots(&out, "run1_", "synthetic run", &samples, &names).unwrap();

    assert_eq!(set.position, out.join("run1_position.png"));
    assert_eq!(set.rates, out.join("run1_rates.png"));
    assert_eq!(set.thrust, out.join("run1_thrust.png"));
    assert_eq!(set.solver_time, out.join("run1_solver_time.png"));

    let blank = blank_png_len(&dir);
    for path in [&set.position, &set.rates, &set.thrust, &set.solver_time] {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(png_size(&bytes), (WIDTH, HEIGHT), "{}", path.display());
        assert!((1000..=1400).contains(&WIDTH) && (800..=1000).contains(&HEIGHT));
        let (share, red, blue) = ink(&bytes);
        assert!(
            share > 0.02,
            "{}: only {share} of the pixels drawn",
            path.display()
        );
        assert!(red && blue, "{}: no red or no blue curve", path.display());
        assert!(
            bytes.len() > 20_000 && bytes.len() > 4 * blank,
            "{} looks blank: {} bytes (blank image: {blank} bytes)",
            path.display(),
            bytes.len()
        );
    }
    cleanup(&dir);
}

#[test]
fn plots_survive_nan_columns_and_a_single_sample() {
    let dir = temp_dir("png-nan");
    let mut samples = trajectory(300);
    for s in &mut samples {
        s.solver_us = f64::NAN;
        s.qp_iterations = f64::NAN;
        s.x_ref = f64::NAN;
        s.phase = 9; // no name for this phase
    }
    let set = write_plots(&dir, "", "", &samples, &["only"]).unwrap();
    let bytes = std::fs::read(&set.solver_time).unwrap();
    assert_eq!(png_size(&bytes), (WIDTH, HEIGHT));

    let one = write_plots(&dir, "one_", "one sample", &samples[..1], &[]).unwrap();
    assert_eq!(
        png_size(&std::fs::read(&one.position).unwrap()),
        (WIDTH, HEIGHT)
    );
    cleanup(&dir);
}

#[test]
fn plots_of_empty_log_are_an_error() {
    let dir = temp_dir("png-empty");
    let err = write_plots(&dir, "e_", "empty", &[], &[]).unwrap_err();
    assert!(matches!(err, PlotError::Empty { .. }), "{err:?}");
    assert!(err.to_string().contains("e_position.png"), "{err}");
    assert!(!dir.join("e_position.png").exists());
    cleanup(&dir);
}
