//! DICOM XA cines written from the twin's frames read back: frames, window/level, geometry,
//! timing, biplane pairing and de-identification. Every file is written here, at test time.

use dicom_core::{DataElement, VR};
use dicom_dictionary_std::tags;
use hnet_dicom::writer::part10_bytes;
use hnet_dicom::{
    BiplaneCine, FRAME_TIME_MS, GeometryTag, ModalityLut, Monochrome, PairingWarning,
    PatientIdentity, Plane, PlaneSeries, WindowLevel, XaCine, cine_views, deidentify,
    identifiers_present, pair_frames, parse, read_cine_file, twin_cine, twin_push_cine, write_xa,
    xa_object,
};
use hnet_units::ImageSize;

const SIZE: ImageSize = ImageSize::square(32);
const FRAMES: usize = 3;

fn series(plane: Plane, name: &str, bytes: &[u8]) -> PlaneSeries {
    let file = read_cine_file(name, bytes).unwrap();
    PlaneSeries::from_files(plane, name, vec![file]).unwrap()
}

#[test]
fn a_twin_cine_reads_back_with_its_frames_geometry_and_timing() {
    let cine = twin_cine(SIZE, FRAMES, 11).unwrap();
    let [a, b] = cine
        .planes
        .each_ref()
        .map(|plane| series(plane.plane, "plane.dcm", &write_xa(plane)));
    let views = cine_views(SIZE);
    for (series, carm) in [(&a, views.a), (&b, views.b)] {
        assert_eq!(series.count(), FRAMES);
        assert_eq!(series.frames.size, SIZE);
        assert_eq!(series.geometry.missing, []);
        let read = series.geometry.carm;
        assert_eq!(read.image_size, carm.image_size);
        for (x, y) in [
            (read.primary_deg, carm.primary_deg),
            (read.secondary_deg, carm.secondary_deg),
            (read.source_to_isocentre_mm, carm.source_to_isocentre_mm),
            (read.source_to_detector_mm, carm.source_to_detector_mm),
            (read.pixel_pitch_mm, carm.pixel_pitch_mm),
        ] {
            assert!((x - y).abs() < 1e-9, "{read:?} vs {carm:?}");
        }
        // The first of the two windows, the full 12-bit range: the twin's 8-bit grey comes back.
        assert_eq!(series.window, Some(WindowLevel::new(2048.0, 4096.0)));
        let times = series.frame_times_s.as_ref().unwrap();
        assert!((times[2] - 2.0 * FRAME_TIME_MS / 1000.0).abs() < 1e-9);
    }
    let written = &cine.planes[0].frames[1];
    let grey = a.grey_frame(1, a.initial_window(1)).unwrap();
    for (g, w) in grey.iter().zip(written) {
        assert!(
            (i32::from(*g) - i32::from((w - 8) / 16)).abs() <= 1,
            "{g} vs {w}"
        );
    }
    let pairing = pair_frames(&a, &b).unwrap();
    assert!(pairing.timed && pairing.warnings.is_empty());
    assert_eq!(pairing.pairs.len(), FRAMES);
    assert!((pairing.pairs[1].time_s.unwrap() - 0.0667).abs() < 1e-9);
}

#[test]
fn a_push_cine_ramps_the_force_up_and_back_on_one_scene_and_pairs_without_notes() {
    let frames = 5;
    let cine = twin_push_cine(SIZE, frames, 4).unwrap();
    let forces: Vec<f32> = cine.forces_n.iter().map(|f| f.magnitude()).collect();
    assert!(forces[0] < 1e-9 && forces[frames - 1] < 1e-9, "{forces:?}");
    assert!(forces[2] > forces[1] && forces[1] > 0.0, "{forces:?}");
    let [a, b] = cine
        .planes
        .each_ref()
        .map(|plane| series(plane.plane, "push.dcm", &write_xa(plane)));
    let cine = BiplaneCine::pair(a, b).unwrap();
    assert_eq!(cine.frame_count(), frames);
    assert_eq!(cine.notes(), Vec::<String>::new());
    let window = cine.series(Plane::A).initial_window(0);
    let (first, middle) = (
        cine.grey_frame(Plane::A, 0, window).unwrap(),
        cine.grey_frame(Plane::A, 2, window).unwrap(),
    );
    assert_ne!(first, middle, "the catheter moves between frames");
    assert_eq!(cine.grey_frame(Plane::B, frames, window), None);
}

/// A small cine of known values: 4x2 pixels, two frames.
fn plain(bits_stored: u16, signed: bool, monochrome: Monochrome) -> XaCine {
    XaCine {
        plane: Plane::A,
        size: ImageSize::new(4, 2),
        bits_stored,
        signed,
        monochrome,
        frames: vec![vec![0, 1, 2, 3, 4, 5, 6, 7], vec![7, 6, 5, 4, 3, 2, 1, 0]],
        carm: None,
        frame_time_ms: None,
        acquisition_date_time: None,
        windows: Vec::new(),
        rescale: None,
        patient: PatientIdentity::fictional(),
        uid_seed: 1,
    }
}

#[test]
fn modality_and_voi_luts_give_8_bit_grey_for_every_pixel_coding() {
    // 8-bit MONOCHROME2 without a window: each frame spans its own range.
    let eight = series(
        Plane::A,
        "eight.dcm",
        &write_xa(&plain(8, false, Monochrome::Two)),
    );
    let grey = eight.grey_frame(0, eight.initial_window(0)).unwrap();
    assert_eq!((grey[0], grey[7]), (0, 255));
    assert!(grey.windows(2).all(|w| w[0] < w[1]));
    // MONOCHROME1: the same values, inverted.
    let one = series(
        Plane::A,
        "one.dcm",
        &write_xa(&plain(8, false, Monochrome::One)),
    );
    assert_eq!(one.grey_frame(0, one.initial_window(0)).unwrap()[0], 255);
    // 16-bit signed with a rescale: stored -3..4 (two's complement) times 2 plus 100.
    let mut signed = plain(16, true, Monochrome::Two);
    signed.frames[0] = [-3i16, -2, -1, 0, 1, 2, 3, 4].map(|v| v as u16).to_vec();
    signed.rescale = Some(ModalityLut {
        slope: 2.0,
        intercept: 100.0,
    });
    signed.windows = vec![(101.0, 1.0), (0.0, 10.0)];
    let read = series(Plane::A, "signed.dcm", &write_xa(&signed));
    assert_eq!(read.frames.range(0), Some((94.0, 108.0)));
    let window = read.initial_window(0);
    assert_eq!(window, WindowLevel::new(101.0, 1.0));
    // The window 101/1 is a step: values up to 100 black, 102 and above white.
    assert_eq!(
        read.grey_frame(0, window).unwrap(),
        [0, 0, 0, 0, 255, 255, 255, 255]
    );
    // Dragging the window is a new value; the frames are untouched.
    let wide = window.dragged(0.0, 30.0);
    let grey = read.grey_frame(0, wide).unwrap();
    assert!(grey.windows(2).all(|w| w[0] < w[1]), "{grey:?}");
    // Without geometry attributes, the plane's default is used and every attribute is listed.
    assert_eq!(read.geometry.missing.len(), 5);
    assert_eq!(
        read.geometry.missing[0],
        GeometryTag::PositionerPrimaryAngle
    );
    assert_eq!(read.geometry.carm.primary_deg, 0.0);
}

#[test]
fn a_folder_of_single_frames_is_one_series_in_instance_order() {
    let times = ["20240501093000.100000", "20240501093000.000000"];
    let files: Vec<_> = times
        .iter()
        .enumerate()
        .map(|(i, when)| {
            let mut cine = plain(8, false, Monochrome::Two);
            cine.frames = vec![vec![i as u16 * 10; 8]];
            cine.acquisition_date_time = Some(when.to_string());
            let mut object = xa_object(&cine);
            object.put(DataElement::new(
                tags::INSTANCE_NUMBER,
                VR::IS,
                (2 - i).to_string(),
            ));
            read_cine_file(&format!("f{i}.dcm"), &part10_bytes(&object)).unwrap()
        })
        .collect();
    let series = PlaneSeries::from_files(Plane::B, "folder", files).unwrap();
    assert_eq!(series.files, ["f1.dcm", "f0.dcm"]);
    assert_eq!(series.frames.frame(0).unwrap()[0], 10);
    let t = series.frame_times_s.clone().unwrap();
    assert!(t[0].abs() < 1e-9 && (t[1] - 0.1).abs() < 1e-6, "{t:?}");
    // Plane B timed, plane A not: paired by index, with a warning.
    let mut untimed = plain(8, false, Monochrome::Two);
    untimed.frames.truncate(2);
    let a = self::series(Plane::A, "a.dcm", &write_xa(&untimed));
    let pairing = pair_frames(&a, &series).unwrap();
    assert!(matches!(
        pairing.warnings[..],
        [PairingWarning::Untimed {
            plane: Plane::A,
            ..
        }]
    ));
}

#[test]
fn pairs_taken_at_different_times_are_reported() {
    let mut a = plain(8, false, Monochrome::Two);
    a.frame_time_ms = Some(100.0);
    let mut b = a.clone();
    b.frame_time_ms = Some(160.0);
    let (a, b) = (
        series(Plane::A, "a.dcm", &write_xa(&a)),
        series(Plane::B, "b.dcm", &write_xa(&b)),
    );
    let pairing = pair_frames(&a, &b).unwrap();
    let warning = pairing.warnings[0].to_string();
    assert!(warning.contains("first frame 2"), "{warning}");
}

#[test]
fn patient_identifiers_are_listed_removed_and_never_read() {
    let cine = plain(8, false, Monochrome::Two);
    let mut object = xa_object(&cine);
    let found = identifiers_present(&object);
    for keyword in [
        "PatientName",
        "PatientID",
        "PatientBirthDate",
        "AccessionNumber",
        "InstitutionName",
    ] {
        assert!(found.contains(&keyword), "{found:?}");
    }
    assert_eq!(deidentify(&mut object), found);
    assert!(identifiers_present(&object).is_empty());
    let bytes = part10_bytes(&object);
    let text = String::from_utf8_lossy(&bytes);
    let patient = PatientIdentity::fictional();
    for value in [&patient.name, &patient.id, &patient.institution] {
        assert!(!text.contains(value.as_str()), "{value}");
    }
    // What the reader keeps of an identified file holds none of it.
    let read = read_cine_file("identified.dcm", &write_xa(&cine)).unwrap();
    let kept = format!("{read:?}");
    assert!(
        !kept.contains("DOE") && !kept.contains("PID-0042"),
        "{kept}"
    );
    assert!(parse("identified.dcm", &write_xa(&cine)).is_ok());
}
