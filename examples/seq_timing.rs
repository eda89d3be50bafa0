use std::time::Instant;
use ghostship::render::{RenderOptions, prepare_tracer, render_scene, MemoRays};
use ghostship::render::sweep::render_sun_sweep;
use ghostship::scene::Scene;
fn main() {
    let mut scene = Scene::from_file(std::path::Path::new("data/scenes/fig12b_novaya_zemlya_strips.toml")).unwrap();
    scene.camera.width = 400; scene.camera.height = 200;
    let atm = scene.atmosphere.load().unwrap();
    let opts = RenderOptions { samples_per_pixel: Some(1), quiet: true, ..RenderOptions::default() };
    let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &opts).unwrap();
    for _ in 0..3 {
        let t = Instant::now();
        let f = render_scene(&scene, tracer.as_ref(), &opts).unwrap();
        eprintln!("one frame {:.1} ms {:?}", t.elapsed().as_secs_f64()*1e3, f.stats);
    }
    let memo = MemoRays::new(tracer.as_ref());
    render_scene(&scene, &memo, &opts).unwrap();
    for _ in 0..3 {
        let t = Instant::now();
        render_scene(&scene, &memo, &opts).unwrap();
        eprintln!("warm memo frame {:.2} ms", t.elapsed().as_secs_f64()*1e3);
    }
    let mut dark = scene.clone(); dark.sun = None;
    let m2 = MemoRays::new(tracer.as_ref());
    render_scene(&dark, &m2, &opts).unwrap();
    for _ in 0..3 {
        let t = Instant::now();
        render_scene(&dark, &m2, &opts).unwrap();
        eprintln!("warm memo frame, no sun {:.2} ms", t.elapsed().as_secs_f64()*1e3);
    }
    let elev: Vec<f64> = (0..100).map(|i| (-3.0 + 0.04 * i as f64).to_radians()).collect();
    for _ in 0..3 {
        let t = Instant::now();
        let fr = render_sun_sweep(&scene, tracer.as_ref(), &opts, &elev).unwrap();
        eprintln!("100 frames {:.1} ms ({})", t.elapsed().as_secs_f64()*1e3, fr.len());
    }
}
