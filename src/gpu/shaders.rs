//! The embedded SPIR-V of every kernel under `glsl/`, compiled by `build.rs`.
//!
//! Each `glsl/<dir>/<name>.comp` becomes a constant `<DIR>_<NAME>: &[u8]`
//! (e.g. `glsl/test/saxpy.comp` → [`TEST_SAXPY`]); vertex and fragment shaders keep their stage
//! as a suffix (`glsl/render/checker.vert` → [`RENDER_CHECKER_VERT`]).

use super::error::{GpuError, GpuResult};

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// Decodes embedded SPIR-V bytes into the words `vkCreateShaderModule` takes (checks the magic
/// number and fixes alignment and endianness).
pub fn words(spv: &[u8]) -> GpuResult<Vec<u32>> {
    ash::util::read_spv(&mut std::io::Cursor::new(spv))
        .map_err(|e| GpuError::Invalid(format!("not SPIR-V: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saxpy_decodes_to_spirv_words() {
        let w = words(TEST_SAXPY).expect("embedded SPIR-V decodes");
        assert_eq!(w[0], 0x0723_0203, "SPIR-V magic number");
    }

    #[test]
    fn truncated_spirv_is_an_error() {
        assert!(words(&TEST_SAXPY[..7]).is_err());
    }
}
