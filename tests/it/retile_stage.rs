//! The `retile` stage in a pipeline: level entities, active mesh, metrics.

use crate::common::*;
use bevy_ecs::prelude::*;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
use surfsynth::stages::retile::SourceCorrespondence;
use surfsynth::world::*;

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

/// Issue 43: a retile pipeline (retile, then synthesis of colours, export)
/// on a mesh with a non-manifold edge runs and writes a valid result; it
/// was refused with exit 2 ("non-manifold edge ... (4 faces meet there)").
#[test]
fn a_retile_pipeline_runs_on_two_cubes_sharing_an_edge() {
    let dir = tempfile::tempdir().unwrap();
    // A face order in which the four triangles on the shared edge were
    // paired across the cubes.
    let (positions, triangles) = two_cubes_sharing_an_edge(3);
    let mesh = dir.path().join("two_cubes.obj");
    std::fs::write(&mesh, triangles_obj(&positions, &triangles)).unwrap();
    let config = dir.path().join("retile.toml");
    std::fs::write(
        &config,
        "seed = 3\n[input]\nmesh = \"two_cubes.obj\"\nexemplar = \"builtin:noise\"\n\n\
         [[stage]]\nkind = \"retile\"\nvertices = 2000\nlevels = 3\n\n\
         [[stage]]\nkind = \"relax_orientation\"\nmode = \"random\"\n\n\
         [[stage]]\nkind = \"init_colours\"\n\n\
         [[stage]]\nkind = \"match\"\nneighbourhoods = [[1, 1], [3, 2], [5, 2]]\n\n\
         [[stage]]\nkind = \"export\"\nformats = [\"ply\"]\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let (code, _, stderr) = run_cli(&[
        "run",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (result, _) = surfsynth::mesh::load_mesh(&out.join("result.ply"), &Default::default())
        .expect("a readable result");
    let info = surfsynth::mesh::MeshInfo::compute(&result);
    assert!(
        (info.vertices as f64 / 2000.0 - 1.0).abs() <= 0.05,
        "{} vertices",
        info.vertices
    );
    assert_eq!(
        (info.non_manifold_edges, info.non_manifold_vertices),
        (0, 0)
    );
    assert_eq!(
        (info.components, info.boundary_loops),
        (2, 0),
        "two closed cubes"
    );
    let area = result.area();
    // The cubes' sharp edges and corners are cut by chords.
    assert!((9.6..=12.1).contains(&area), "area {area} of 12");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(
        metrics["stages"][0]["metrics"]["input_cut_nonmanifold_edges"], 1,
        "{}",
        metrics["stages"][0]["metrics"]
    );
}
