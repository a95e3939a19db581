//! Any bytes as a constraints file (`vertex x y z` lines) for a mesh whose vertex count is the
//! first byte's value times 1000 plus the second's: the reader returns constraints or a located
//! error, never panics.
#![no_main]

use std::path::Path;

use foldfree::vol::constraints;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (nv, rest) = match data {
        [a, b, rest @ ..] => (*a as usize * 1000 + *b as usize, rest),
        _ => return,
    };
    let text = String::from_utf8_lossy(rest);
    if let Ok(c) = constraints::parse_constraints(&text, Path::new("fuzz.txt"), nv) {
        assert!(c.iter().all(|(v, p)| (*v as usize) < nv && p.iter().all(|x| x.is_finite())));
    }
});
