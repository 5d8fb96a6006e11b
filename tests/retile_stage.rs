//! The `retile` stage in a pipeline: level entities, active mesh, metrics.

mod common;
use bevy_ecs::prelude::*;
use common::*;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
use surfsynth::stages::retile::SourceCorrespondence;
use surfsynth::stages::world::*;

#[test]
fn retile_stage_spawns_a_pyramid_and_activates_the_finest_level() {
    let text = format!(
        "seed = 1\n[input]\nmesh = \"{}\"\nexemplar = \"builtin:noise\"\n\n[[stage]]\nkind = \"retile\"\nvertices = 4000\nlevels = 3\n",
        data_file("meshes/bunny_1k8.obj").display()
    );
    let p = Pipeline::from_source(ConfigSource::from_text("t.toml", &text)).unwrap();
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let mut w = World::new();
    run_in_world(&p, &mut w, input).unwrap();
    let mut q = w.query::<(Entity, &MeshLevel, &Geometry, &SourceCorrespondence)>();
    let mut levels: Vec<(u8, usize, Entity)> = q
        .iter(&w)
        .map(|(e, l, g, c)| {
            assert_eq!(c.face.len(), g.0.vertex_count());
            (l.0, g.0.vertex_count(), e)
        })
        .collect();
    levels.sort();
    assert_eq!(levels.len(), 3, "three level entities");
    for (i, target) in [4000usize, 1000, 250].iter().enumerate() {
        let n = levels[i].1 as f64;
        assert!(
            (n / *target as f64 - 1.0).abs() <= 0.05,
            "level {i}: {n} vs {target}"
        );
    }
    assert_eq!(
        w.resource::<ActiveMesh>().0,
        levels[0].2,
        "finest level is active"
    );
    let m = &w.resource::<Metrics>().stages[0];
    let cv0 = m["level_edge_length_cv"][0].as_f64().unwrap();
    assert!(cv0 <= 0.25, "edge-length CV {cv0}");
}
