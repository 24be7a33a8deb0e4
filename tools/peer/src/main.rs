//! The four scenes of `tools/side_by_side.py` traced by eulumdat-goniosim, a Monte Carlo
//! photon tracer for luminaires, so that its speed is measured in the same run as ours.
//!
//!     peer-bench <isotropic|lambertian|mirror_cup|diffuse_cup> <photons> [seed]
//!
//! Prints one JSON object: the scene, the photons traced and detected, and the tracing's
//! wall seconds as the library reports them (the caller measures the process's CPU time).

use eulumdat_goniosim::*;
use nalgebra::{Point3, Unit, Vector3};
use std::env;
use std::process;

const FLUX: f64 = 1000.0; // lm, as the stages
const C_STEP: f64 = 15.0; // deg, the grid side_by_side.py measures on
const G_STEP: f64 = 5.0; // deg

fn down() -> Unit<Vector3<f64>> {
    Unit::new_unchecked(Vector3::new(0.0, 0.0, -1.0))
}

/// A Lambertian point source at the rim of an open cylinder (25 mm radius, 50 mm long)
/// of the given material, emitting down into it.
fn cup(material: MaterialParams) -> Scene {
    SceneBuilder::new()
        .source(Source::Lambertian { position: Point3::origin(), normal: down(), flux_lm: FLUX })
        .reflector(material, ReflectorPlacement {
            distance_mm: 25.0,
            length_mm: 50.0,
            side: ReflectorSide::Surround,
        })
        .build()
}

fn scene(name: &str) -> Option<Scene> {
    Some(match name {
        "isotropic" => bare_isotropic(FLUX),
        "lambertian" => bare_lambertian(FLUX),
        "mirror_cup" => cup(catalog::mirror_aluminum()),
        "diffuse_cup" => cup(catalog::white_paint()),
        _ => return None,
    })
}

fn main() {
    let args: Vec<String> = env::args().collect();
    let usage = "usage: peer-bench <isotropic|lambertian|mirror_cup|diffuse_cup> <photons> [seed]";
    if args.len() < 3 {
        eprintln!("{usage}");
        process::exit(2);
    }
    let Some(scene) = scene(&args[1]) else {
        eprintln!("unknown scene {:?}; {usage}", args[1]);
        process::exit(2);
    };
    let photons: u64 = args[2].parse().unwrap_or_else(|_| {
        eprintln!("photons must be a whole number, not {:?}", args[2]);
        process::exit(2);
    });
    let seed: u64 = args.get(3).map_or(42, |s| s.parse().unwrap_or(42));
    let config = TracerConfig {
        num_photons: photons,
        detector_c_resolution: C_STEP,
        detector_g_resolution: G_STEP,
        seed,
        ..TracerConfig::default()
    };
    let result = Tracer::trace(&scene, &config);
    println!(
        "{{\"scene\": \"{}\", \"photons\": {}, \"detected\": {}, \"seconds\": {}}}",
        args[1],
        result.stats.photons_traced,
        result.stats.photons_detected,
        result.stats.elapsed.as_secs_f64()
    );
}
