//! Map files: bytes → the path `MapStore::load_dir` takes (UTF-8 text, `maps::parse` with its
//! size check and every validation rule, then `Arena::new`).
//!
//! Besides "no panic", it checks what the server relies on: a map that passes validation
//! builds an arena, and the JSON the server serves back for it (`GET /api/maps/{name}`,
//! `maps::to_file`) passes validation again.
#![no_main]

use lasertag::maps;
use lasertag_core::sim::arena::Arena;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // `load_dir` reads files with `read_to_string`: bytes that are not UTF-8 are refused there.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(def) = maps::parse(text) else {
        return;
    };
    let served = maps::to_file(&def);
    if let Err(e) = maps::validate(&served) {
        panic!("a valid map, served back, is refused: {e}\nserved: {served:?}");
    }
    // Building the arena of a large map costs up to 400k clearance cells; keep each input fast
    // (the arena code is the same at any size, only the grid's cell count changes).
    if (def.width as f64) * (def.height as f64) <= 400.0 {
        let _ = Arena::new(def);
    }
});
