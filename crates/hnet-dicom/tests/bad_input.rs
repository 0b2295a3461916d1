//! Bad DICOM input: each case is an error that names the file and the reason, never a panic.

use dicom_core::value::PixelFragmentSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use hnet_dicom::writer::part10_bytes;
use hnet_dicom::{
    DicomError, PairingError, PatientIdentity, Plane, PlaneSeries, XaCine, pair_frames,
    read_cine_file, twin_cine, write_xa, xa_object,
};
use hnet_units::ImageSize;

const NAME: &str = "run-07/plane-a.dcm";

fn cine() -> XaCine {
    twin_cine(ImageSize::square(32), 3, 3).unwrap().planes[0].clone()
}

fn message(error: DicomError) -> String {
    assert_eq!(error.file(), NAME);
    let text = error.to_string();
    assert!(text.starts_with(NAME), "{text}");
    text
}

#[test]
fn bytes_that_are_not_dicom_are_named() {
    for bytes in [&b"\x89PNG\r\n\x1a\n"[..], &[0u8; 300][..], b""] {
        let error = read_cine_file(NAME, bytes).unwrap_err();
        assert!(matches!(error, DicomError::NotDicom { .. }), "{error:?}");
        assert!(message(error).contains("not a DICOM file"));
    }
}

#[test]
fn jpeg_2000_is_refused_with_its_transfer_syntax() {
    let mut object = xa_object(&cine());
    object.update_meta(|meta| meta.transfer_syntax = uids::JPEG2000.into());
    object.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PixelFragmentSequence::new(Vec::<u32>::new(), vec![vec![0xFFu8, 0x4F, 0xFF, 0x51]]),
    ));
    let error = read_cine_file(NAME, &part10_bytes(&object)).unwrap_err();
    assert!(
        matches!(error, DicomError::UnsupportedTransferSyntax { .. }),
        "{error:?}"
    );
    let text = message(error);
    assert!(
        text.contains("1.2.840.10008.1.2.4.91") && text.contains("JPEG 2000"),
        "{text}"
    );
}

#[test]
fn colour_and_32_bit_pixels_are_refused() {
    let mut colour = xa_object(&cine());
    colour.put(DataElement::new(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        PrimitiveValue::from("RGB"),
    ));
    colour.put(DataElement::new(
        tags::SAMPLES_PER_PIXEL,
        VR::US,
        PrimitiveValue::from(3u16),
    ));
    let error = read_cine_file(NAME, &part10_bytes(&colour)).unwrap_err();
    assert!(matches!(error, DicomError::Colour { .. }), "{error:?}");
    assert!(message(error).contains("colour images (RGB"));

    let mut wide = xa_object(&cine());
    for tag in [tags::BITS_ALLOCATED, tags::BITS_STORED] {
        wide.put(DataElement::new(tag, VR::US, PrimitiveValue::from(32u16)));
    }
    let error = read_cine_file(NAME, &part10_bytes(&wide)).unwrap_err();
    assert!(matches!(error, DicomError::BitDepth { .. }), "{error:?}");
    assert!(message(error).contains("32-bit pixels"));
}

#[test]
fn truncated_files_are_named() {
    let bytes = write_xa(&cine());
    // Cut inside the pixel data, and inside the header.
    for keep in [bytes.len() - 100, bytes.len() / 2, 700] {
        let error = read_cine_file(NAME, &bytes[..keep]).unwrap_err();
        assert!(
            matches!(error, DicomError::Truncated { .. }),
            "{keep}: {error:?}"
        );
        assert!(message(error).contains("truncated"));
    }
}

#[test]
fn planes_with_different_frame_counts_are_not_paired() {
    let mut short = cine();
    short.frames.truncate(2);
    short.patient = PatientIdentity::fictional();
    let read = |plane, name: &str, cine: &XaCine| {
        PlaneSeries::from_files(
            plane,
            name,
            vec![read_cine_file(name, &write_xa(cine)).unwrap()],
        )
        .unwrap()
    };
    let a = read(Plane::A, "a.dcm", &cine());
    let b = read(Plane::B, "b.dcm", &short);
    let error = pair_frames(&a, &b).unwrap_err();
    assert!(matches!(
        error,
        PairingError::FrameCounts {
            frames_a: 3,
            frames_b: 2,
            ..
        }
    ));
    let text = error.to_string();
    assert!(text.contains("a.dcm") && text.contains("b.dcm"), "{text}");
    // What was loaded before is untouched and still usable.
    assert_eq!(a.count(), 3);
}

// ---------------------------------------------------------------------------------------------
// Property tests (issue #13, docs/reliability.md): arbitrary bytes, mutated XA files and headers
// claiming any size are a cine that holds together or an error naming the file, never a panic;
// a written cine reads back exactly. That reading never asks for memory out of proportion to the
// file is checked too (the bugs these found are fixed in `file.rs`; docs/reliability.md).
// ---------------------------------------------------------------------------------------------

/// Records each thread's largest allocation request (see `properties::largest_allocation`).
#[global_allocator]
static ALLOCATOR: properties::PeakAllocator = properties::PeakAllocator;

mod properties {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;
    use std::sync::OnceLock;

    use dicom_core::value::PixelFragmentSequence;
    use dicom_core::{DataElement, PrimitiveValue, Tag, VR};
    use dicom_dictionary_std::{tags, uids};
    use hnet_dicom::writer::part10_bytes;
    use hnet_dicom::{
        CineFile, ModalityLut, Monochrome, PatientIdentity, Plane, WindowLevel, XaCine,
        read_cine_file, twin_cine, write_xa, xa_object,
    };
    use hnet_mutations::{Edit, cases, edits, mutate_near_start};
    use hnet_twin::simulator::carm::CArm;
    use hnet_units::ImageSize;
    use proptest::prelude::*;

    const NAME: &str = "cines/plane-a.dcm";

    /// Allocation requests above this are refused (a null pointer), never granted: a header
    /// claiming gigabytes cannot exhaust CI's memory. `try_reserve` callers then get an error,
    /// anything else aborts the test binary (a visible failure). The request is still recorded.
    const REFUSED_ABOVE: usize = 64 << 20;

    thread_local! {
        static LARGEST: Cell<usize> = const { Cell::new(0) };
    }

    /// The system allocator, recording the largest request of each thread.
    pub struct PeakAllocator;

    fn note(size: usize) -> bool {
        let _ = LARGEST.try_with(|largest| largest.set(largest.get().max(size)));
        size <= REFUSED_ABOVE
    }

    // SAFETY: forwards to the system allocator; refusing (a null pointer) is allowed by
    // `GlobalAlloc`.
    unsafe impl GlobalAlloc for PeakAllocator {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            if !note(layout.size()) {
                return std::ptr::null_mut();
            }
            unsafe { System.alloc(layout) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            unsafe { System.dealloc(ptr, layout) }
        }
        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            if !note(layout.size()) {
                return std::ptr::null_mut();
            }
            unsafe { System.alloc_zeroed(layout) }
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new: usize) -> *mut u8 {
            if !note(new) {
                return std::ptr::null_mut();
            }
            unsafe { System.realloc(ptr, layout, new) }
        }
    }

    /// What `f` returns and the largest single allocation it asked for, bytes.
    fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
        LARGEST.with(|largest| largest.set(0));
        let value = f();
        (value, LARGEST.with(Cell::get))
    }

    /// The most a file of `len` bytes may make the reader ask for at once: a few copies of the
    /// file (its pixel data as bytes and as 16-bit codes, frame times) and dicom-rs's own
    /// allowance of 16 MiB for a decoded encapsulated frame.
    fn allowance(len: usize) -> usize {
        (16 << 20) + 64 * len
    }

    /// What [`read_checked`] holds a read to.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Expect {
        /// A cine that holds together or an error naming the file, never a panic; a request
        /// above `REFUSED_ABOVE` was refused, and must have come back as an error, not an abort.
        /// What CI checks.
        NoPanic,
        /// That, and no single allocation out of proportion to the file ([`allowance`]), and no
        /// cine of zero pixels (docs/reliability.md, "Bugs found and fixed").
        Bounded,
    }

    /// Reads `bytes` as `NAME` and checks the outcome against `expect` (a panic is a failure
    /// that proptest reports with its input).
    fn read_checked(bytes: &[u8], expect: Expect) -> Result<Option<CineFile>, TestCaseError> {
        let (read, largest) = largest_allocation(|| read_cine_file(NAME, bytes));
        if expect == Expect::Bounded {
            prop_assert!(
                largest <= allowance(bytes.len()),
                "a {}-byte file asked for {largest} bytes at once",
                bytes.len()
            );
        }
        match read {
            Ok(cine) => {
                let frames = &cine.frames;
                prop_assert_eq!(&cine.name, NAME);
                if expect == Expect::Bounded {
                    prop_assert!(frames.size.pixels() > 0, "a cine of {}", frames.size);
                }
                prop_assert_eq!(frames.codes.len(), frames.count() * frames.size.pixels());
                prop_assert!(frames.codes.len() <= bytes.len());
                if let Some(times) = &cine.timing.frame_times_s {
                    prop_assert_eq!(times.len(), frames.count());
                }
                Ok(Some(cine))
            }
            Err(error) => {
                prop_assert_eq!(error.file(), NAME);
                let text = error.to_string();
                prop_assert!(text.starts_with(NAME), "{}", text);
                Ok(None)
            }
        }
    }

    /// Valid files: both planes of twin cines of 2 frames of 16 x 16 pixels, two seeds.
    fn valid_files() -> &'static [Vec<u8>] {
        static FILES: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
        FILES.get_or_init(|| {
            (0..2)
                .flat_map(|seed| twin_cine(ImageSize::square(16), 2, seed).unwrap().planes)
                .map(|plane| write_xa(&plane))
                .collect()
        })
    }

    /// Where a file's Pixel Data element starts (its tag, in explicit VR little endian).
    fn pixel_data_offset(bytes: &[u8]) -> usize {
        bytes
            .windows(4)
            .position(|w| w == [0xE0, 0x7F, 0x10, 0x00])
            .expect("a written file has Pixel Data")
    }

    /// The end of a file's meta group (preamble, `DICM`, group 0002): where its data set starts.
    fn data_set_offset(bytes: &[u8]) -> usize {
        // (0002,0000) UL, 4-byte length, then the group's length after it.
        let length = u32::from_le_bytes(bytes[140..144].try_into().unwrap());
        144 + length as usize
    }

    /// A plain XA cine: `frames` frames of `size`, `bits` bits stored, a fixed pattern of values.
    fn plain_cine(size: ImageSize, bits: u16, frames: usize) -> XaCine {
        let pixels = size.pixels();
        XaCine {
            plane: Plane::A,
            size,
            bits_stored: bits,
            signed: false,
            monochrome: Monochrome::Two,
            frames: (0..frames)
                .map(|f| {
                    (0..pixels)
                        .map(|i| ((i * 7 + f * 13) % (1 << bits)) as u16)
                        .collect()
                })
                .collect(),
            carm: Some(CArm::cardiac(10.0, -5.0, size)),
            frame_time_ms: Some(66.7),
            acquisition_date_time: None,
            windows: vec![],
            rescale: None,
            patient: PatientIdentity::fictional(),
            uid_seed: 1,
        }
    }

    /// A number as a header may claim it: small, zero, large, past any range, not whole.
    fn claimed() -> impl Strategy<Value = String> {
        prop_oneof![
            3 => (0u64..40).prop_map(|n| n.to_string()),
            2 => (1u64 << 15..1 << 32).prop_map(|n| n.to_string()),
            1 => any::<u64>().prop_map(|n| n.to_string()),
            1 => any::<i64>().prop_map(|n| n.to_string()),
            1 => Just("1e30".to_string()),
            1 => Just("2.5".to_string()),
            1 => Just("NaN".to_string()),
        ]
    }

    /// `tag` set to `value` under the VR `vr` (US and UL values wrapped to their width; text
    /// VRs take the text).
    fn put(object: &mut dicom_object::DefaultDicomObject, tag: Tag, vr: VR, value: &str) {
        let number = value.parse::<f64>().unwrap_or(0.0);
        let value = match vr {
            VR::US => PrimitiveValue::from(number as i64 as u16),
            VR::UL => PrimitiveValue::from(number as i64 as u32),
            _ => PrimitiveValue::from(value),
        };
        object.put(DataElement::new(tag, vr, value));
    }

    /// A 16 x 16, 8-bit cine of 2 frames as JPEG baseline (dicom-rs's encoder), or `None` when
    /// this build cannot encode it.
    fn jpeg_file() -> Option<&'static [u8]> {
        static FILE: OnceLock<Option<Vec<u8>>> = OnceLock::new();
        FILE.get_or_init(|| {
            use dicom_pixeldata::Transcode;
            let mut object = xa_object(&plain_cine(ImageSize::square(16), 8, 2));
            object
                .transcode(&dicom_transfer_syntax_registry::entries::JPEG_BASELINE.erased())
                .ok()?;
            Some(part10_bytes(&object))
        })
        .as_deref()
    }

    /// PackBits as DICOM's RLE Lossless codes a byte segment (PS3.5 G.3.1): runs of 3 to 128
    /// equal bytes as a replicate run (`1 - n` as a signed byte, then the byte), the rest as
    /// literal runs of at most 128 bytes (`n - 1`, then the bytes). The segment is padded to an
    /// even length.
    fn pack_bits(bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut literal: Vec<u8> = Vec::new();
        let flush = |literal: &mut Vec<u8>, out: &mut Vec<u8>| {
            for chunk in literal.chunks(128) {
                out.push((chunk.len() - 1) as u8);
                out.extend_from_slice(chunk);
            }
            literal.clear();
        };
        let mut i = 0;
        while i < bytes.len() {
            let run = bytes[i..]
                .iter()
                .take(128)
                .take_while(|&&b| b == bytes[i])
                .count();
            if run >= 3 {
                flush(&mut literal, &mut out);
                out.push((1 - run as i16) as i8 as u8);
                out.push(bytes[i]);
                i += run;
            } else {
                literal.push(bytes[i]);
                i += 1;
            }
        }
        flush(&mut literal, &mut out);
        if out.len() % 2 == 1 {
            out.push(0x80); // a no-op run
        }
        out
    }

    /// One frame of 8-bit pixels as an RLE Lossless fragment: the 64-byte header (one segment
    /// at offset 64, 14 unused offsets) and the segment.
    fn rle_frame(pixels: &[u8]) -> Vec<u8> {
        let mut fragment = vec![0u8; 64];
        fragment[0..4].copy_from_slice(&1u32.to_le_bytes());
        fragment[4..8].copy_from_slice(&64u32.to_le_bytes());
        fragment.extend(pack_bits(pixels));
        fragment
    }

    /// A 16 x 16, 8-bit cine of 2 frames as RLE Lossless (dicom-rs decodes RLE but has no
    /// encoder, so the fragments are coded by [`rle_frame`]): each frame holds runs (a constant
    /// half) and literals (the `plain_cine` pattern).
    fn rle_file() -> &'static [u8] {
        static FILE: OnceLock<Vec<u8>> = OnceLock::new();
        FILE.get_or_init(|| {
            let cine = plain_cine(ImageSize::square(16), 8, 2);
            let mut object = xa_object(&cine);
            object.update_meta(|meta| meta.transfer_syntax = uids::RLE_LOSSLESS.into());
            let fragments: Vec<Vec<u8>> = rle_frames(&cine).iter().map(|f| rle_frame(f)).collect();
            object.put(DataElement::new(
                tags::PIXEL_DATA,
                VR::OB,
                PixelFragmentSequence::new(Vec::<u32>::new(), fragments),
            ));
            part10_bytes(&object)
        })
    }

    /// The 8-bit pixels [`rle_file`] codes, frame by frame: the first half of each frame
    /// constant, the second `plain_cine`'s pattern.
    fn rle_frames(cine: &XaCine) -> Vec<Vec<u8>> {
        cine.frames
            .iter()
            .map(|frame| {
                let half = frame.len() / 2;
                frame
                    .iter()
                    .enumerate()
                    .map(|(i, &v)| if i < half { 77 } else { v as u8 })
                    .collect()
            })
            .collect()
    }

    /// Random cines as `write_xa` takes them: any size up to 8 x 8, 1-4 frames, every pixel
    /// coding, geometry, timing, windows and rescale, or none of them.
    fn any_cine() -> impl Strategy<Value = XaCine> {
        let coding = (1usize..=8, 1usize..=8, 1u16..=16, 1usize..=4);
        let header = (
            any::<bool>().prop_map(|b| if b { Plane::A } else { Plane::B }),
            any::<bool>(),
            any::<bool>().prop_map(|b| if b { Monochrome::One } else { Monochrome::Two }),
            proptest::option::of((
                -180.0f64..180.0,
                -90.0f64..90.0,
                400.0f64..1000.0,
                1000.0f64..1400.0,
                0.05f64..1.0,
            )),
            proptest::option::of(1.0f64..1000.0),
            proptest::collection::vec((-5000.0f64..5000.0, 1.0f64..10000.0), 0..3),
            proptest::option::of((
                prop_oneof![0.01f64..100.0, -100.0f64..-0.01],
                -5000.0f64..5000.0,
            )),
            any::<u64>(),
        );
        (coding, header).prop_flat_map(
            |(
                (width, height, bits, frames),
                (plane, signed, monochrome, carm, frame_time_ms, windows, rescale, uid_seed),
            )| {
                let values = proptest::collection::vec(
                    proptest::collection::vec(0u32..1 << bits, width * height),
                    frames,
                );
                values.prop_map(move |values| {
                    let size = ImageSize::new(width, height);
                    XaCine {
                        plane,
                        size,
                        bits_stored: bits,
                        signed,
                        monochrome,
                        frames: values
                            .into_iter()
                            .map(|f| f.into_iter().map(|v| v as u16).collect())
                            .collect(),
                        carm: carm.map(|(primary, secondary, iso, detector, pitch)| CArm {
                            primary_deg: primary,
                            secondary_deg: secondary,
                            source_to_isocentre_mm: iso,
                            source_to_detector_mm: detector,
                            pixel_pitch_mm: pitch,
                            image_size: size,
                        }),
                        frame_time_ms,
                        acquisition_date_time: None,
                        windows: windows.clone(),
                        rescale: rescale.map(|(slope, intercept)| ModalityLut { slope, intercept }),
                        patient: PatientIdentity::fictional(),
                        uid_seed,
                    }
                })
            },
        )
    }

    /// The stored value a `bits`-bit sample `raw` stands for (two's complement when `signed`).
    fn stored_value(raw: u16, bits: u16, signed: bool) -> i32 {
        let value = i32::from(raw) & ((1 << bits) - 1);
        if signed && value >= 1 << (bits - 1) {
            value - (1 << bits)
        } else {
            value
        }
    }

    /// Arbitrary bytes, a third of them behind a preamble and `DICM`, a third behind a valid
    /// file meta group too (random data set bytes): both reach the parser proper.
    fn any_bytes(prefix: usize, bytes: &[u8], expect: Expect) -> Result<(), TestCaseError> {
        let valid = &valid_files()[0];
        let head: &[u8] = match prefix {
            0 => &[],
            1 => &valid[..132],
            _ => &valid[..data_set_offset(valid)],
        };
        read_checked(&[head, bytes].concat(), expect).map(drop)
    }

    /// Valid file `file` with `edits`, every other one in the header (meta group and
    /// attributes, up to the pixel data's own header), where it changes what the file claims.
    fn mutated(file: usize, edits: &[Edit], expect: Expect) -> Result<(), TestCaseError> {
        let valid = &valid_files()[file];
        let header = pixel_data_offset(valid) + 12;
        read_checked(&mutate_near_start(valid.clone(), edits, header), expect).map(drop)
    }

    /// Valid file `file` whose Pixel Data claims `length` bytes (explicit VR little endian OW:
    /// tag, VR, two reserved bytes, then the length).
    fn pixel_data_claiming(file: usize, length: u32, expect: Expect) -> Result<(), TestCaseError> {
        let mut bytes = valid_files()[file].clone();
        let at = pixel_data_offset(&bytes) + 8;
        bytes[at..at + 4].copy_from_slice(&length.to_le_bytes());
        let read = read_checked(&bytes, expect)?;
        prop_assert!(
            read.is_none() || length == 1024,
            "{} bytes read as a cine",
            length
        );
        Ok(())
    }

    /// The JPEG cine whose frames' SOF0 (FFC0, length, precision, height, width) claim
    /// `height` x `width`, then `edits`.
    fn jpeg_claiming(
        [height, width]: [u16; 2],
        edits: Option<&[Edit]>,
        expect: Expect,
    ) -> Result<(), TestCaseError> {
        let jpeg = jpeg_file().expect("dicom-rs encodes JPEG baseline in this build");
        let pixel_data = pixel_data_offset(jpeg);
        let mut bytes = jpeg.to_vec();
        for at in
            (pixel_data..jpeg.len().saturating_sub(9)).filter(|&i| jpeg[i..i + 2] == [0xFF, 0xC0])
        {
            bytes[at + 5..at + 7].copy_from_slice(&height.to_be_bytes());
            bytes[at + 7..at + 9].copy_from_slice(&width.to_be_bytes());
        }
        if let Some(edits) = edits {
            bytes = mutate_near_start(bytes, edits, usize::MAX);
        }
        read_checked(&bytes, expect).map(drop)
    }

    /// Any length, the largest ones often.
    fn any_length() -> impl Strategy<Value = u32> {
        prop_oneof![1 => Just(u32::MAX), 1 => Just(u32::MAX - 1), 3 => any::<u32>()]
    }

    proptest! {
        #![proptest_config(cases(128))]

        #[test]
        fn any_bytes_are_a_cine_or_an_error_naming_the_file(
            prefix in 0usize..3,
            bytes in proptest::collection::vec(any::<u8>(), 0..2048),
        ) {
            any_bytes(prefix, &bytes, Expect::NoPanic)?;
        }

        #[test]
        fn a_mutated_cine_is_a_cine_or_an_error_naming_the_file(file in 0usize..4, edits in edits()) {
            mutated(file, &edits, Expect::NoPanic)?;
        }

        #[test]
        fn a_mutated_rle_cine_is_a_cine_or_an_error_naming_the_file(edits in edits()) {
            // Anywhere in the file: half the edits land in the RLE headers and segments.
            let bytes = hnet_mutations::mutate(rle_file().to_vec(), &edits);
            read_checked(&bytes, Expect::Bounded)?;
        }

        #[test]
        fn a_pixel_data_length_claiming_any_size_is_an_error(file in 0usize..4, length in any_length()) {
            pixel_data_claiming(file, length, Expect::NoPanic)?;
        }

        #[test]
        fn a_header_claiming_any_size_is_refused_or_read_whole(
            rows in (claimed(), proptest::sample::select(vec![VR::US, VR::UL, VR::IS])),
            columns in (claimed(), proptest::sample::select(vec![VR::US, VR::UL, VR::IS])),
            frames in (claimed(), proptest::sample::select(vec![VR::IS, VR::UL])),
            bits in proptest::sample::select(vec![8u16, 16]),
        ) {
            // A real 8 x 8 cine of 3 frames whose header then claims other sizes: refused, or
            // read from the pixel data it has (never more frames than its bytes hold).
            let mut object = xa_object(&plain_cine(ImageSize::square(8), bits.min(12), 3));
            put(&mut object, tags::ROWS, rows.1, &rows.0);
            put(&mut object, tags::COLUMNS, columns.1, &columns.0);
            put(&mut object, tags::NUMBER_OF_FRAMES, frames.1, &frames.0);
            if let Some(cine) = read_checked(&part10_bytes(&object), Expect::NoPanic)? {
                prop_assert!(cine.frames.codes.len() <= 3 * 64);
            }
        }

        // The bugs these found (docs/reliability.md) are fixed in `file.rs`:
        // `check_element_lengths`, `check_jpeg_frames` and the refusal of a zero Rows/Columns.

        /// dicom-rs's parser reserves and zero-fills an element's claimed length (up to 4 GiB)
        /// before reading it: a 2 KB file can ask for gigabytes.
        #[test]
        fn any_bytes_ask_for_memory_in_proportion_to_the_file(
            prefix in 0usize..3,
            bytes in proptest::collection::vec(any::<u8>(), 0..2048),
        ) {
            any_bytes(prefix, &bytes, Expect::Bounded)?;
        }

        #[test]
        fn a_mutated_cine_asks_for_memory_in_proportion_to_the_file(file in 0usize..4, edits in edits()) {
            mutated(file, &edits, Expect::Bounded)?;
        }

        #[test]
        fn a_pixel_data_length_claiming_any_size_is_refused_before_it_is_allocated(
            file in 0usize..4,
            length in any_length(),
        ) {
            pixel_data_claiming(file, length, Expect::Bounded)?;
        }

        /// Aborts the test binary (jpeg-decoder allocates the frame its SOF claims, infallibly),
        /// or panics in dicom-rs's JPEG adapter when the frame is larger than Rows x Columns.
        #[test]
        fn a_jpeg_frame_claiming_any_size_is_refused_or_bounded(
            size in [any::<u16>(), any::<u16>()],
            edits in proptest::option::of(edits()),
        ) {
            jpeg_claiming(size, edits.as_deref(), Expect::Bounded)?;
        }

        #[test]
        fn written_cines_read_back_exactly(cine in any_cine()) {
            let file = read_cine_file(NAME, &write_xa(&cine)).unwrap();
            let frames = &file.frames;
            prop_assert_eq!(frames.size, cine.size);
            prop_assert_eq!(frames.count(), cine.frames.len());
            prop_assert_eq!(frames.coding.bits_stored, cine.bits_stored);
            prop_assert_eq!(frames.coding.signed, cine.signed);
            prop_assert_eq!(frames.monochrome, cine.monochrome);
            for (index, written) in cine.frames.iter().enumerate() {
                let read: Vec<i32> = frames
                    .frame(index)
                    .unwrap()
                    .iter()
                    .map(|&code| frames.coding.stored_value(code))
                    .collect();
                let expected: Vec<i32> = written
                    .iter()
                    .map(|&raw| stored_value(raw, cine.bits_stored, cine.signed))
                    .collect();
                prop_assert_eq!(read, expected, "frame {}", index);
            }
            let lut = cine.rescale.unwrap_or_default();
            prop_assert_eq!(frames.modality, lut);
            prop_assert_eq!(
                file.window,
                cine.windows.first().map(|&(centre, width)| WindowLevel::new(centre, width))
            );
            // Frame times: Frame Time (ms) apart, in seconds, bit for bit.
            let times = cine.frame_time_ms.map(|ms| {
                (0..cine.frames.len()).map(|i| i as f64 * ms / 1000.0).collect::<Vec<_>>()
            });
            prop_assert_eq!(&file.timing.frame_times_s, &times);
            // C-arm angles, distances and pixel pitch as written, bit for bit.
            let geometry = &file.geometry;
            prop_assert_eq!(geometry.image_size, cine.size);
            match &cine.carm {
                Some(carm) => {
                    prop_assert_eq!(geometry.primary_deg, Some(carm.primary_deg));
                    prop_assert_eq!(geometry.secondary_deg, Some(carm.secondary_deg));
                    prop_assert_eq!(geometry.source_to_detector_mm, Some(carm.source_to_detector_mm));
                    prop_assert_eq!(geometry.source_to_patient_mm, Some(carm.source_to_isocentre_mm));
                    prop_assert_eq!(
                        geometry.imager_pixel_spacing_mm,
                        Some([carm.pixel_pitch_mm, carm.pixel_pitch_mm])
                    );
                    prop_assert_eq!(&geometry.carm(cine.plane).carm, carm);
                }
                None => {
                    prop_assert_eq!(geometry.primary_deg, None);
                    prop_assert_eq!(geometry.carm(cine.plane).missing.len(), 5);
                }
            }
        }
    }

    // The smallest inputs of the bugs above, one regression test each.

    /// dicom-parser reserves 4 GiB for a 2 KB file's Pixel Data claiming 4 GiB - 2 bytes.
    #[test]
    fn a_pixel_data_length_of_4_gib_is_refused_before_it_is_allocated() {
        pixel_data_claiming(0, u32::MAX - 1, Expect::Bounded).unwrap();
    }

    /// Rows 0 (or Columns 0): read as a cine of zero frames of 0 pixels, not refused.
    #[test]
    fn zero_rows_or_columns_are_refused() {
        for tag in [tags::ROWS, tags::COLUMNS] {
            let mut object = xa_object(&plain_cine(ImageSize::square(8), 8, 3));
            put(&mut object, tag, VR::US, "0");
            let read = read_cine_file(NAME, &part10_bytes(&object));
            assert!(read.is_err(), "{tag}: {read:?}");
        }
    }

    /// A JPEG frame larger than Rows x Columns: dicom-rs's JPEG adapter copies it past the end
    /// of its frame buffer.
    #[test]
    fn a_jpeg_frame_larger_than_its_header_is_refused() {
        jpeg_claiming([64, 64], None, Expect::Bounded).unwrap();
    }

    /// A JPEG frame claiming 65535 x 65535 pixels: jpeg-decoder allocates them (4 GiB)
    /// infallibly, which aborts the process.
    #[test]
    fn a_jpeg_frame_claiming_65535_square_is_refused() {
        jpeg_claiming([u16::MAX, u16::MAX], None, Expect::Bounded).unwrap();
    }

    /// The JPEG properties mean something only if this build writes JPEG: it does.
    #[test]
    fn a_jpeg_cine_is_written_and_read() {
        let bytes = jpeg_file().expect("dicom-rs encodes JPEG baseline in this build");
        let cine = read_cine_file(NAME, bytes).unwrap();
        assert_eq!(cine.frames.count(), 2);
        assert_eq!(cine.frames.size, ImageSize::square(16));
    }

    /// The RLE property means something only if the file it mutates is a valid RLE cine: its
    /// frames read back exactly (dicom-rs's RLE decoder).
    #[test]
    fn an_rle_cine_is_written_and_read() {
        let cine = read_cine_file(NAME, rle_file()).unwrap();
        let expected = rle_frames(&plain_cine(ImageSize::square(16), 8, 2));
        assert_eq!(cine.frames.count(), 2);
        let codes: Vec<u8> = cine.frames.codes.iter().map(|&c| c as u8).collect();
        assert_eq!(codes, expected.concat());
    }

    /// Found by `a_mutated_rle_cine_is_a_cine_or_an_error_naming_the_file`: an RLE header
    /// claiming 173 segments made dicom-rs's RLE adapter read its offsets past the fragment (a
    /// panic), and a segment that decodes short made it index past the decoded bytes.
    #[test]
    fn rle_frames_that_would_overrun_the_decoder_are_refused() {
        let valid = rle_file();
        // Pixel Data's header (12 bytes), the empty offset table item (8), the first
        // fragment's item header (8): then its RLE header, which starts with the segment count.
        let header = pixel_data_offset(valid) + 28;
        assert_eq!(valid[header..header + 8], [1, 0, 0, 0, 64, 0, 0, 0]);
        let mut bytes = valid.to_vec();
        bytes[header] = 173;
        let error = read_checked(&bytes, Expect::Bounded).unwrap();
        assert!(error.is_none());
        let text = read_cine_file(NAME, &bytes).unwrap_err().to_string();
        assert!(text.contains("RLE frame (0) of 173 segments"), "{text}");
        // The first frame's segment cut to a replicate run of 100 bytes (of 256 needed).
        let mut short = valid.to_vec();
        short[header + 64] = (1 - 100i16) as i8 as u8;
        let text = read_cine_file(NAME, &short).unwrap_err().to_string();
        assert!(text.contains("decodes to"), "{text}");
    }

    /// Found by the same property: an encapsulated cine whose Pixel Data tag lost a byte
    /// ((7FE0,0010) became (7F00,0010), an OB of undefined length) made dicom-rs ask for 2.6 GB.
    #[test]
    fn an_undefined_length_outside_sequences_and_pixel_data_is_refused() {
        let mut bytes = rle_file().to_vec();
        let tag = pixel_data_offset(&bytes);
        bytes[tag] = 0;
        assert!(read_checked(&bytes, Expect::Bounded).unwrap().is_none());
        let text = read_cine_file(NAME, &bytes).unwrap_err().to_string();
        assert!(
            text.contains("element (7F00,0010) of VR OB has an undefined length"),
            "{text}"
        );
    }

    /// An encapsulated frame of no bytes (what the JPEG property's edits may leave): an error.
    #[test]
    fn an_encapsulated_frame_of_no_bytes_is_an_error() {
        let mut object = xa_object(&plain_cine(ImageSize::square(8), 8, 1));
        object.update_meta(|meta| meta.transfer_syntax = uids::JPEG_BASELINE8_BIT.into());
        object.put(DataElement::new(
            tags::PIXEL_DATA,
            VR::OB,
            PixelFragmentSequence::new(Vec::<u32>::new(), vec![Vec::<u8>::new()]),
        ));
        let error = read_cine_file(NAME, &part10_bytes(&object)).unwrap_err();
        assert_eq!(error.file(), NAME);
    }
}
