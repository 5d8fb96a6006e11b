//! TEMPORARY STUB (replaced by helper-b's merge).
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(default)]
pub struct ExemplarOptions {
    pub size: u32,
}
