#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    looming::fuzzing::message(looming::decode::MessageKind::PointCloud2, data);
});
