//! TEMPORARY STUB (replaced by helper-b's merge).
use super::{Image, ImageError, builtin::ExemplarOptions};
pub fn exemplar_from_spec(
    spec: &str,
    _b: &std::path::Path,
    _o: &ExemplarOptions,
) -> Result<(Image, String), ImageError> {
    let mut img = Image::new(16, 16, 3);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = ((i * 7919) % 101) as f32 / 100.0;
    }
    Ok((img, spec.to_string()))
}
