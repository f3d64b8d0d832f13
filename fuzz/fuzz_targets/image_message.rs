//! Image and calibration messages of recordings (ROS 2 CDR and Foxglove protobuf, raw
//! and compressed): decoded into a view or a message, never a panic; a view converts
//! into the frame buffers without reading past its data.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mrsmap::io::compressed_image::decompress;
use mrsmap::io::image_msg::{ImageHolder, MessageKind, decode_calibration, decode_image, to_depth16, to_rgb8};

const KINDS: [MessageKind; 6] = [
    MessageKind::RosImage,
    MessageKind::RosCameraInfo,
    MessageKind::RosCompressedImage,
    MessageKind::FoxgloveImage,
    MessageKind::FoxgloveCompressedImage,
    MessageKind::FoxgloveCalibration,
];

/// Format strings of compressed images as `image_transport` and Foxglove write them.
const FORMATS: [&str; 6] = [
    "jpeg",
    "png",
    "rgb8; jpeg compressed bgr8",
    "16UC1; compressedDepth png",
    "32FC1; compressedDepth",
    "16UC1; compressedDepth rvl",
];

fuzz_target!(|data: &[u8]| {
    let Some((&selector, message)) = data.split_first() else { return };
    let kind = KINDS[selector as usize % KINDS.len()];
    let mut holder = ImageHolder::default();
    if let Ok(view) = decode_image(kind, message, &mut holder) {
        if view.format.is_depth() {
            let mut depth = Vec::new();
            to_depth16(&view, &mut depth);
            assert_eq!(depth.len(), view.width * view.height);
        } else {
            let mut rgb = Vec::new();
            to_rgb8(&view, &mut rgb);
            assert_eq!(rgb.len(), 3 * view.width * view.height);
        }
    }
    if let Ok(camera) = decode_calibration(kind, message) {
        // A calibration that decodes is one a frame can use.
        assert!(camera.validate().is_ok(), "accepted an invalid calibration: {camera:?}");
    }
    let mut out = Vec::new();
    if let Ok(image) = decompress(FORMATS[(selector as usize / KINDS.len()) % FORMATS.len()], message, &mut out) {
        assert!(out.len() >= image.width * image.height);
    }
});
