#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    looming::fuzzing::scenario_json(data);
});
