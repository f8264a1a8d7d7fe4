//! The canonical scenes load exactly as docs/SCENES.md gives them.

use glam::Vec3;
use relume_base::scene::format::load_scene_file;
use relume_base::types::{Environment, Light, Material, Scene};
use relume_tests::graphs_dir;

fn load(name: &str) -> (Scene, Vec<String>) {
    let l = load_scene_file(&graphs_dir().join("scenes").join(format!("{name}.ron"))).unwrap_or_else(|e| panic!("{e}"));
    (l.scene, l.notes)
}

fn object<'a>(s: &'a Scene, name: &str) -> &'a relume_base::types::Object {
    s.objects.iter().find(|o| o.name == name).unwrap_or_else(|| panic!("no {name}"))
}

#[test]
fn cornell_has_the_eight_mitsuba_objects_and_a_light_facing_down() {
    let (s, _) = load("cornell");
    let names: Vec<_> = s.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["floor", "ceiling", "back", "green-wall", "red-wall", "small-box", "large-box", "light"]);
    let light = object(&s, "light");
    assert_eq!(light.emission, Vec3::new(18.387, 13.9873, 6.75357));
    assert_eq!(light.material, Material::Lambert { albedo: Vec3::new(0.885809, 0.698859, 0.666422) });
    for t in light.triangles.clone() {
        assert!(s.normal_area(t as usize).0.y < -0.99, "the light faces down");
    }
    assert_eq!(object(&s, "red-wall").material, Material::Lambert { albedo: Vec3::new(0.570068, 0.043014, 0.044371) });
    assert_eq!((s.camera.fov_deg, s.camera.width, s.camera.height), (39.3077, 256, 256));
    assert_eq!(s.camera.origin, Vec3::new(0.0, 0.0, 3.9));
    // Walls face into the box: the floor's normal points up.
    assert!(s.normal_area(object(&s, "floor").triangles.start as usize).0.y > 0.99);
}

#[test]
fn cornell_bunny_diffuse_is_cornell_bunny_with_every_surface_diffuse() {
    let (d, _) = load("cornell-bunny-diffuse");
    let (g, _) = load("cornell-bunny");
    assert_eq!(d.positions, g.positions, "the same geometry as cornell-bunny");
    assert_eq!(d.triangles, g.triangles);
    assert!(d.objects.iter().all(|o| matches!(o.material, Material::Lambert { .. })), "every surface diffuse");
    assert_eq!(object(&d, "bunny").material, object(&d, "floor").material, "the bunny in the box's white");
    assert!(d.objects.iter().all(|o| !o.dynamic));
}

#[test]
fn cornell_bunny_places_the_bunny_on_the_floor_with_dynamic_materials() {
    let (s, _) = load("cornell-bunny");
    let bunny = object(&s, "bunny");
    assert!(bunny.dynamic);
    assert_eq!(bunny.material, Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.4), exponent: 180.0 });
    assert!(s.objects.iter().all(|o| o.name != "small-box" && o.name != "large-box"));
    assert!(object(&s, "floor").dynamic && !object(&s, "red-wall").dynamic);
    let lo = bunny.triangles.clone().flat_map(|t| s.corners(t as usize)).fold(f32::INFINITY, |m, p| m.min(p.y));
    assert!((lo - -1.0).abs() < 0.02, "bunny rests on the floor at y = -1: lowest point {lo}");
    assert!(bunny.triangles.len() > 69_000);
}

#[test]
fn cornell_heavy_stands_three_subdivided_meshes_on_the_floor_apart() {
    let (s, _) = load("cornell-heavy");
    assert_eq!(s.triangles.len(), 472_632, "the box's 12 triangles and the meshes at 4, 16 and 16 times theirs");
    assert!(s.objects.iter().all(|o| matches!(o.material, Material::Lambert { .. }) && !o.dynamic));
    let bounds = |name: &str| {
        let o = object(&s, name);
        o.triangles
            .clone()
            .flat_map(|t| s.corners(t as usize))
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)))
    };
    let boxes: Vec<(Vec3, Vec3)> = ["bunny", "spot", "teapot"].iter().map(|n| bounds(n)).collect();
    for (name, (lo, hi)) in ["bunny", "spot", "teapot"].iter().zip(&boxes) {
        assert!((lo.y - -1.0).abs() < 0.02, "{name} rests on the floor: lowest point {}", lo.y);
        assert!(lo.cmpge(Vec3::splat(-1.01)).all() && hi.cmple(Vec3::splat(1.0)).all(), "{name} inside the box: {lo} {hi}");
    }
    for i in 0..3 {
        for j in i + 1..3 {
            let ((a0, a1), (b0, b1)) = (boxes[i], boxes[j]);
            let overlap = a0.cmplt(b1).all() && b0.cmplt(a1).all();
            assert!(!overlap, "meshes {i} and {j} overlap: {a0} {a1} against {b0} {b1}");
        }
    }
}

#[test]
fn ring_envlit_and_glass_load_with_their_lights() {
    let (ring, _) = load("ring");
    assert_eq!(ring.lights, vec![Light::Point { position: Vec3::new(-3.0, 1.2, 0.0), intensity: Vec3::splat(40.0) }]);
    let (env, _) = load("envlit");
    let Some(Environment::Map(m)) = &env.environment else { panic!("envlit has a map") };
    assert_eq!((m.width, m.height), (512, 256));
    let sun = m.eval(Vec3::new(0.663, 0.643, 0.383).normalize());
    assert!(sun.max_element() > 1000.0, "the sun is where docs/SCENES.md says: {sun}");
    let (glass, _) = load("glass");
    assert!(matches!(object(&glass, "glass").material, Material::Dielectric { ior, medium: None } if ior == 1.5));
    assert_eq!(object(&glass, "light").emission, Vec3::splat(400.0));
}

#[test]
fn cornell_spot_textures_the_cow_and_the_path_tracer_shows_the_texture() {
    let (s, notes) = load("cornell-spot");
    let spot = object(&s, "spot");
    assert!(spot.dynamic && notes.is_empty(), "{notes:?}");
    assert_eq!(spot.material, Material::BlinnPhong { kd: Vec3::splat(0.7), ks: Vec3::splat(0.2), exponent: 40.0 });
    let kd = spot.maps.kd.as_ref().expect("a Kd map");
    assert_eq!((kd.width, kd.height), (256, 256));
    assert!(spot.maps.ks.is_none() && spot.maps.exponent.is_none());
    assert_eq!(s.uvs.len(), s.positions.len(), "every vertex has a UV (zero off the cow)");
    let lo = spot.triangles.clone().flat_map(|t| s.corners(t as usize)).fold(f32::INFINITY, |m, p| m.min(p.y));
    assert!((lo - -1.0).abs() < 0.01, "Spot stands on the floor at y = -1: lowest point {lo}");
    // The cow's hide is dark under its spots: with the map, the pixels showing Spot are darker
    // than without it, and the walls do not change by more than the noise and the bounce.
    let mut small = s.clone();
    small.camera.width = 48;
    small.camera.height = 48;
    let mut plain = small.clone();
    plain.objects.iter_mut().for_each(|o| *o.maps = Default::default());
    let accel = relume_base::types::Accel::build(&small, relume_base::types::accel::BuildQuality::Fast);
    let pt = relume_base::reference::path_trace::PathTrace {
        spp: 16,
        max_depth: 2,
        min_depth: 1,
        rr_depth: 5,
        seed: 1,
        fresnel_reflection: true,
    };
    let render = |sc: &Scene| relume_base::reference::path_trace::render(sc, &accel, &pt, None).unwrap().0;
    let (textured, untextured) = (render(&small), render(&plain));
    let cam = relume_base::render::camera::CameraRays::new(&small.camera);
    let spot_index = s.objects.iter().position(|o| o.name == "spot").unwrap() as u32;
    let (mut on, mut on_plain, mut off, mut off_plain) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for y in 0..48 {
        for x in 0..48 {
            let (o, d) = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
            let hit = accel.intersect(o, d, 0.0, f32::INFINITY).map(|h| small.tri_object[h.tri as usize]);
            let (a, b) = (textured.pixels[y * 48 + x][1] as f64, untextured.pixels[y * 48 + x][1] as f64);
            if hit == Some(spot_index) {
                (on, on_plain) = (on + a, on_plain + b);
            } else {
                (off, off_plain) = (off + a, off_plain + b);
            }
        }
    }
    assert!(on < 0.9 * on_plain, "Spot with its map {on}, without {on_plain}");
    assert!((off - off_plain).abs() < 0.05 * off_plain, "elsewhere {off} vs {off_plain}");
}

#[test]
fn texture_maps_need_uvs_an_image_and_a_material_they_apply_to() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    std::fs::copy(graphs_dir().join("assets/spot/spot_kd.png"), dir.path().join("kd.png")).unwrap();
    let cam = "camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8)";
    write("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write("uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n");
    let err = |text: String| load_scene_file(&write("s.ron", &text)).err().unwrap();
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5, kd_map: \"kd.png\") }},\n shapes: [Obj(path: \"tri.obj\", material: \"m\")])"));
    assert!(e.contains("object \"tri\"") && e.contains("no UVs"), "{e}");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5, ks_map: \"kd.png\") }},\n shapes: [])"));
    assert!(e.contains("s.ron:2:") && e.contains("`ks_map` does not apply"), "{e}");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5, kd_map: \"none.png\") }},\n shapes: [])"));
    assert!(e.contains("s.ron:2:") && e.contains("none.png"), "{e}");
    write("bad.png", "not a png");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5, kd_map: \"bad.png\") }},\n shapes: [])"));
    assert!(e.contains("bad.png: not a readable PNG"), "{e}");
    // With UVs it loads, and the texture file is a dependency of the scene.
    let ok = load_scene_file(&write(
        "ok.ron",
        &format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5, kd_map: \"kd.png\") }},\n shapes: [Obj(path: \"uv.obj\", material: \"m\")])"),
    ))
    .unwrap();
    assert!(ok.scene.objects[0].maps.kd.is_some());
    assert!(ok.files.iter().any(|(p, _)| p.ends_with("kd.png")));
}

#[test]
fn texture_maps_holding_nan_inf_or_negative_texels_are_refused_with_the_texel() {
    use relume_base::image::io::write_exr;
    use relume_base::types::Image;
    let dir = tempfile::tempdir().unwrap();
    let cam = "camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8)";
    std::fs::write(dir.path().join("uv.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n").unwrap();
    // An all-NaN Kd map rendered the object black with nothing said; an all-inf Ks map wrote
    // pixels near 1e37.
    for (map, bad, want) in [("kd_map", f32::NAN, "NaN"), ("ks_map", f32::INFINITY, "inf"), ("exponent_map", -1.0, "-1.0")] {
        let file = format!("{map}.exr");
        write_exr(&dir.path().join(&file), &Image::from_fn(4, 3, |x, y| if (x, y) == (2, 1) { [0.5, bad, 0.5] } else { [0.5; 3] }))
            .unwrap();
        let scene = dir.path().join("s.ron");
        std::fs::write(
            &scene,
            format!("Scene({cam},\n materials: {{ \"m\": BlinnPhong(kd: 0.5, ks: 0.2, exponent: 20, {map}: \"{file}\") }},\n shapes: [Obj(path: \"uv.obj\", material: \"m\")])"),
        )
        .unwrap();
        let e = load_scene_file(&scene).err().unwrap();
        assert!(e.contains("s.ron:2:") && e.contains(&format!("`{map}`")) && e.contains("texel (2, 1)") && e.contains(want), "{e}");
        assert!(e.contains("finite and ≥ 0"), "{e}");
    }
}

#[test]
fn scene_errors_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let cam = "camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8)";
    write("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let err = |text: String| load_scene_file(&write("s.ron", &text)).err().unwrap();
    let e = err(format!("Scene({cam},\n shapes: [Obj(path: \"tri.obj\",\n material: \"gold\")])"));
    assert!(e.contains("s.ron:3:12: unknown material \"gold\""), "{e}");
    let e = err(format!("Scene({cam},\n shapes: [Obj(path: \"missing.obj\", material: \"m\")], materials: {{}})"));
    assert!(e.contains("s.ron:2:") && e.contains("unknown material"), "{e}");
    let e = err(format!(
        "Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5) }},\n shapes: [Obj(path: \"missing.obj\", material: \"m\")])"
    ));
    assert!(e.contains("s.ron:3:21: cannot read") && e.contains("missing.obj"), "{e}");
    write("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n");
    let e =
        err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5) }},\n shapes: [Obj(path: \"nan.obj\", material: \"m\")])"));
    assert!(e.contains("nan.obj:3: `v` has a non-finite value"), "{e}");
    write("bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 9\n");
    let e =
        err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5) }},\n shapes: [Obj(path: \"bad.obj\", material: \"m\")])"));
    assert!(e.contains("bad.obj:3: face index 9"), "{e}");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Lambert(albedo: 0.5) }},\n shapes: [Obj(path: \"tri.obj\", material: \"m\")],\n environment: Map(path: \"sky.hdr\"))"));
    assert!(e.contains("s.ron:4:") && e.contains("sky.hdr"), "{e}");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": BlinnPhong(kd: 0.7, ks: 0.5, exponent: 10) }},\n shapes: [])"));
    assert!(e.contains("s.ron:2:") && e.contains("exceeds 1"), "{e}");
    let e = err(format!("Scene({cam},\n materials: {{ \"m\": Plastic(x: 1) }},\n shapes: [])"));
    assert!(e.contains("s.ron:2:20: unknown material `Plastic`"), "{e}");
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 1\n").unwrap();
    std::fs::write(dir.path().join("s.ron"), "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8), materials: { \"m\": Lambert(albedo: 0.5) }, shapes: [Obj(path: \"m.obj\", material: \"m\")], lights: [Point(position: (0, 0, 1), intensity: 1)])").unwrap();
    let l = load_scene_file(&dir.path().join("s.ron")).unwrap();
    assert_eq!(l.scene.triangles.len(), 1);
    assert_eq!(l.notes, ["2 zero-area triangles dropped"]);
    assert!(l.scene.normals.iter().all(|n| n.is_finite()));
}

/// OBJ and MTL mistakes reach the person through the scene loader with the OBJ's or the
/// MTL's own file and line (the scene file's colours were already checked; the MTL's were
/// not, and ran with non-finite albedo and emission).
#[test]
fn obj_and_mtl_errors_name_their_own_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("s.ron"), "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8),\n shapes: [Obj(path: \"m.obj\")])").unwrap();
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let err = |obj: &str, mtl: Option<&str>| {
        std::fs::write(d.join("m.obj"), obj).unwrap();
        match mtl {
            Some(m) => std::fs::write(d.join("m.mtl"), m).unwrap(),
            None => {
                let _ = std::fs::remove_file(d.join("m.mtl"));
            }
        }
        let e = load_scene_file(&d.join("s.ron")).err().expect("an error");
        e.replace(&format!("{}/", d.display()), "")
    };
    let obj = format!("mtllib m.mtl\n{tri}usemtl a\nf 1 2 3\n");
    assert_eq!(err(&obj, Some("newmtl a\nKd -5 nan 2\n")), "m.mtl:2: `Kd` has a non-finite value `nan`");
    assert_eq!(err(&obj, Some("newmtl a\nKd 0.5 0.5 0.5\nKe inf 0 0\n")), "m.mtl:3: `Ke` has a non-finite value `inf`");
    assert_eq!(err(&obj, Some("newmtl a\nKd 2 0 0\n")), "m.mtl:2: `Kd` = 2 0 0 must lie in [0, 1]");
    let mtl = Some("newmtl a\nKd 0.5 0.5 0.5\nnewmtl b\nKd 1 1 1\n");
    assert_eq!(
        err(&format!("mtllib m.mtl\n{tri}garbage here\nusemtl a\nf 1 2 3\n"), mtl),
        "m.obj:5: `garbage` is not an OBJ statement (expected v, vt, vn, f, o, g, usemtl, mtllib, s or a # comment)"
    );
    let e = err(&format!("mtllib other.mtl\n{tri}usemtl a\nf 1 2 3\n"), mtl);
    assert!(e.starts_with("m.obj:1: cannot read the material library \"other.mtl\""), "{e}");
    assert_eq!(
        err(&format!("mtllib m.mtl\n{tri}vn 0 0 1\nusemtl a\nf 1//1 2//1 3//3\n"), mtl),
        "m.obj:7: face index 3 refers to a normal that does not exist (only 1 so far)"
    );
    assert_eq!(
        err(&format!("mtllib m.mtl\n{tri}usemtl c\nf 1 2 3\n"), mtl),
        "m.obj:5: `usemtl c`: material \"c\" is not defined in m.mtl (it defines: a, b)"
    );
}

/// The MTL a scene's OBJ names is a dependency of the scene (editing it re-runs LoadScene).
#[test]
fn the_cornell_mtl_is_a_dependency() {
    let l = load_scene_file(&graphs_dir().join("scenes/cornell.ron")).unwrap();
    assert!(l.files.iter().any(|(p, _)| p.ends_with("cornell_box.mtl")), "{:?}", l.files);
}
