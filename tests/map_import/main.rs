//! Importing maps researchers already have (ROS map_server, MovingAI) and exporting ours to
//! ROS, on maps each test draws itself (`drawn.rs`): the walls and extent come out exactly
//! as drawn, an export imports back to the same cells, a robot's laser on an imported map
//! measures the drawn walls, and the maps folder, the CLI and bad files behave.

mod drawn;

use std::path::Path;
use std::sync::Arc;

use drawn::{Picture, analytic_range, folder, polygon, room, spawns_reach_each_other};
use lasertag::maps::cli::{self, ExportArgs, ImportArgs, MapCommand};
use lasertag::maps::import::{ImportOptions, Imported, import_file};
use lasertag::maps::{MapFile, MapStore, ros};
use lasertag_core::sim::arena::{Arena, point_in_polygon};
use lasertag_core::world::{MatchConfig, Placement, World};
use nalgebra::Point2;

#[test]
fn a_ros_map_imports_to_exactly_the_walls_drawn_from_every_image_kind() {
    let dir = folder("golden-ros");
    let pic = room();
    let mut first: Option<Imported> = None;
    for kind in ["p5", "p2", "png", "rgb-negated", "rgba-scale"] {
        let yaml = pic.write(&dir, &format!("lab-{kind}"), kind, [-3.0, -2.0]);
        let imported = import_file(&yaml, &ImportOptions::default()).unwrap();
        let f = &imported.file;
        assert_eq!((f.width, f.height), (10.0, 7.5), "{kind}");
        // The wall from the top and the crate touch the border; the pillar stands free. Each
        // is one rectangle, in order of their lowest row, then column.
        let want: Vec<Vec<[f64; 2]>> = [pic.walls[2], pic.walls[0], pic.walls[1]]
            .into_iter()
            .map(polygon)
            .collect();
        assert_eq!(f.obstacles, want, "{kind}");
        // The unknown margin was cropped: the arena's (0, 0) is two cells in from the image's
        // corner at (-3, -2).
        assert_eq!(imported.origin, [-2.5, -1.5, 0.0], "{kind}");
        assert_eq!(imported.cells, [40, 30]);
        assert_eq!(f.name, format!("lab-{kind}"));
        assert!(f.robot_spawns.len() >= 2 && f.opponent_spawns.len() >= 2);
        assert!((4..=16).contains(&f.landmarks.len()));
        match &first {
            None => first = Some(imported),
            Some(a) => {
                assert_eq!(a.file.robot_spawns, f.robot_spawns, "{kind}");
                assert_eq!(a.file.opponent_spawns, f.opponent_spawns, "{kind}");
            }
        }
    }
    let arena = Arena::new(first.unwrap().def);
    spawns_reach_each_other(&arena);
}

#[test]
fn keeping_the_extent_keeps_the_unknown_margin_as_wall() {
    let dir = folder("keep-extent");
    let yaml = room().write(&dir, "lab", "p5", [-3.0, -2.0]);
    let options = ImportOptions {
        crop: false,
        ..ImportOptions::default()
    };
    let imported = import_file(&yaml, &options).unwrap();
    assert_eq!((imported.file.width, imported.file.height), (11.0, 8.5));
    assert_eq!(imported.origin, [-3.0, -2.0, 0.0]);
    // Every cell of the margin is wall, so the free cells are the room's.
    let def = &imported.def;
    let free = |x: f32, y: f32| {
        !def.obstacles
            .iter()
            .any(|p| point_in_polygon(Point2::new(x, y), p))
    };
    assert!(!free(0.3, 4.0) && !free(10.7, 4.0) && free(1.0, 4.0));
}

#[test]
fn a_movingai_grid_imports_with_water_as_wall_and_swamp_as_floor() {
    let dir = folder("golden-movingai");
    let text = "type octile\nheight 6\nwidth 10\nmap\n\
                @@@@@@@@@@\n\
                @.....T..@\n\
                @..SS.T..@\n\
                @..SS....@\n\
                @WW......@\n\
                @@@@@@@@@@\n";
    let path = dir.join("Arena2.map");
    std::fs::write(&path, text).unwrap();
    let imported = import_file(&path, &ImportOptions::default()).unwrap();
    let f = &imported.file;
    // The `@` ring holds no free cell: cropped, leaving 8 × 4 cells of 1 m.
    assert_eq!((f.name.as_str(), f.width, f.height), ("arena2", 8.0, 4.0));
    assert_eq!(
        f.obstacles,
        vec![polygon([0.0, 0.0, 2.0, 1.0]), polygon([5.0, 2.0, 6.0, 4.0])]
    );
    let half = ImportOptions {
        cell_size: Some(0.5),
        ..ImportOptions::default()
    };
    let f = import_file(&path, &half).unwrap().file;
    assert_eq!((f.width, f.height), (4.0, 2.0));
    assert_eq!(f.obstacles[1], polygon([2.5, 1.0, 3.0, 2.0]));
}

#[test]
fn an_export_imports_back_to_the_same_map() {
    let dir = folder("round-trip");
    let yaml = room().write(&dir, "lab", "p5", [-3.0, -2.0]);
    let first = import_file(&yaml, &ImportOptions::default()).unwrap();
    let out = dir.join("exported");
    let done = ros::export(&first.def, first.origin, 0.25, &out).unwrap();
    assert_eq!(
        done.pixels,
        [42, 32],
        "the arena and a ring of border pixels"
    );
    let again = import_file(&done.yaml, &ImportOptions::default()).unwrap();
    assert_eq!(again.file, first.file);
    for k in 0..3 {
        assert!(
            (again.origin[k] - first.origin[k]).abs() < 1e-9,
            "{:?}",
            again.origin
        );
    }
    // The exported image holds the same occupancy as the source inside the border ring.
    let (src, _) = ros::read(&yaml).unwrap();
    let (back, _) = ros::read(&done.yaml).unwrap();
    for r in 0..30 {
        for c in 0..40 {
            assert_eq!(
                back.is_blocked(c + 1, r + 1),
                src.is_blocked(c + 2, r + 2),
                "cell ({c}, {r})"
            );
        }
    }
    assert!((0..42).all(|c| back.is_blocked(c, 0) && back.is_blocked(c, 31)));

    // A hand-made map with a slanted wall: its export, imported, keeps every wall cell.
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("maps/office.json"))
            .unwrap();
    let office = lasertag::maps::parse(&text).unwrap();
    let done = ros::export(&office, [0.0; 3], 0.1, &out).unwrap();
    let (grid, origin) = ros::read(&done.yaml).unwrap();
    assert!((origin[0] + 0.1).abs() < 1e-9 && (origin[1] + 0.1).abs() < 1e-9);
    let arena = Arena::new(office.clone());
    for r in 1..grid.rows - 1 {
        for c in 1..grid.cols - 1 {
            let p = Point2::new((c as f32 - 0.5) * 0.1, (r as f32 - 0.5) * 0.1);
            if arena.inside_obstacle(p) {
                assert!(grid.is_blocked(c, r), "office wall at {p:?} lost");
            }
        }
    }
    let reimported = import_file(&done.yaml, &ImportOptions::default()).unwrap();
    assert_eq!(
        (reimported.file.width, reimported.file.height),
        (24.0, 16.0)
    );
}

#[test]
fn a_robot_on_an_imported_ros_map_scans_the_walls_drawn_within_a_cell() {
    let dir = folder("scan");
    // Walls whose faces fall between pixel edges, at 5 cm a pixel.
    let pic = Picture {
        cols: 200,
        rows: 140,
        margin: 3,
        res: 0.05,
        walls: vec![[6.03, 2.51, 6.77, 5.38], [1.12, 5.91, 4.46, 6.23]],
    };
    let yaml = pic.write(&dir, "scan", "p5", [12.0, -40.0]);
    let imported = import_file(&yaml, &ImportOptions::default()).unwrap();
    assert_eq!((imported.file.width, imported.file.height), (10.0, 7.0));
    let arena = Arc::new(Arena::new(imported.def));
    let mut config = MatchConfig {
        robots: 1,
        opponents: 1,
        localisation: false,
        placement: Placement::Given {
            robots: vec![[3.1, 3.3, 0.4]],
            opponents: vec![[0.6, 0.6]],
        },
        ..MatchConfig::default()
    };
    config.physics.laser_noise = 0.0;
    let range = config.physics.laser_range as f64;
    let (beams, fov) = (config.physics.laser_beams, config.physics.laser_fov as f64);
    let mut world = World::new(arena, config).unwrap();
    world.sense();
    let scan = &world.robots[0].scan.ranges;
    assert_eq!(scan.len(), beams);
    let mut checked = 0;
    for (i, &measured) in scan.iter().enumerate() {
        let bearing = 0.4 + -fov / 2.0 + fov * i as f64 / (beams - 1) as f64;
        let dir = [bearing.cos(), bearing.sin()];
        let want = analytic_range([3.1, 3.3], dir, &pic.walls, [10.0, 7.0]).min(range);
        // A face drawn in pixels lies within half a pixel of the drawn one along its normal;
        // along a beam that is half a pixel over the cosine of the incidence, which stays
        // within one pixel for beams within 60° of the normal. Grazing beams and beams that
        // pass a corner within a pixel are not measured.
        let hit = [3.1 + dir[0] * want, 3.3 + dir[1] * want];
        let near_corner = pic.walls.iter().any(|q| {
            [[q[0], q[1]], [q[2], q[1]], [q[2], q[3]], [q[0], q[3]]]
                .iter()
                .any(|c| (c[0] - hit[0]).hypot(c[1] - hit[1]) < 2.0 * pic.res)
        });
        let on_vertical_face = pic.walls.iter().any(|q| {
            ((hit[0] - q[0]).abs() < 1e-6 || (hit[0] - q[2]).abs() < 1e-6)
                && hit[1] >= q[1]
                && hit[1] <= q[3]
        }) || hit[0].abs() < 1e-6
            || (hit[0] - 10.0).abs() < 1e-6;
        let cos = if on_vertical_face {
            dir[0].abs()
        } else {
            dir[1].abs()
        };
        if want >= range || near_corner || cos < 0.5 {
            continue;
        }
        checked += 1;
        assert!(
            (measured as f64 - want).abs() <= pic.res + 1e-3,
            "beam {i} at {bearing:.3} rad: measured {measured}, the drawn walls are {want:.3} away"
        );
    }
    assert!(checked > 90, "only {checked} beams checked");
}

#[test]
fn the_maps_folder_loads_ros_and_movingai_maps_beside_json() {
    let dir = folder("store");
    room().write(&dir, "Lab Floor", "p5", [0.0, 0.0]);
    std::fs::write(
        dir.join("tiny.map"),
        "type octile\nheight 3\nwidth 6\nmap\n......\n......\n......\n",
    )
    .unwrap();
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("maps");
    std::fs::copy(maps.join("office.json"), dir.join("office.json")).unwrap();
    let store = MapStore::load_dir(&dir).unwrap();
    let names: Vec<&str> = store.iter().map(|m| m.arena.def.name.as_str()).collect();
    assert_eq!(names, ["lab-floor", "office", "tiny"]);
    for m in store.iter() {
        spawns_reach_each_other(&m.arena);
    }

    // Two files that give one name are refused, naming both.
    std::fs::write(
        dir.join("office.map"),
        "type octile\nheight 3\nwidth 6\nmap\n......\n......\n......\n",
    )
    .unwrap();
    let e = MapStore::load_dir(&dir).unwrap_err().to_string();
    assert!(e.contains("office.map") && e.contains("office.json"), "{e}");
    std::fs::remove_file(dir.join("office.map")).unwrap();

    // A broken file fails the load with its name and line.
    std::fs::write(
        dir.join("bad.map"),
        "type octile\nheight 1\nwidth 2\nmap\n.?\n",
    )
    .unwrap();
    let e = MapStore::load_dir(&dir).unwrap_err().to_string();
    assert!(e.contains("bad.map: line 5: column 2"), "{e}");
}

#[test]
fn bad_files_are_errors_that_name_the_file_and_what_is_wrong() {
    let dir = folder("errors");
    let options = ImportOptions::default();
    let check = |path: &Path, want: &[&str]| {
        let e = import_file(path, &options).unwrap_err().to_string();
        for w in want {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    };
    let yaml = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let good = "image: lab.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n\
                occupied_thresh: 0.65\nfree_thresh: 0.196\n";
    check(
        &yaml("nofile.yaml", good),
        &["nofile.yaml: image:", "lab.pgm is not a file"],
    );
    check(
        &yaml("neg.yaml", &good.replace("0.05", "-0.05")),
        &["neg.yaml: resolution: -0.05 must be"],
    );
    check(
        &yaml("mode.yaml", &format!("{good}mode: fuzzy\n")),
        &["mode.yaml: mode: \"fuzzy\""],
    );
    // An image too large is refused from its header, before its pixels are read.
    std::fs::write(dir.join("huge.pgm"), "P5 5000 5000 255\n").unwrap();
    check(
        &yaml("huge.yaml", &good.replace("lab.pgm", "huge.pgm")),
        &["huge.pgm: the image is 5000 × 5000 pixels, the limit is"],
    );
    // A grid wider than the 500 m limit says which option helps.
    let row = ".".repeat(600);
    let wide = format!("type octile\nheight 2\nwidth 600\nmap\n{row}\n{row}\n");
    std::fs::write(dir.join("wide.map"), wide).unwrap();
    check(
        &dir.join("wide.map"),
        &["wide.map: the map is 600 m", "--cell-size"],
    );
    // All wall: no free cell.
    std::fs::write(
        dir.join("solid.map"),
        "type octile\nheight 1\nwidth 2\nmap\n@T\n",
    )
    .unwrap();
    check(
        &dir.join("solid.map"),
        &["solid.map: the map has no free cell"],
    );
}

#[test]
fn too_many_walls_are_refused_until_the_grid_is_coarsened() {
    let dir = folder("coarsen");
    // A wall cell at every fourth column and every second row: 51 × 50 lone cells, 10,200
    // vertices.
    let rows: Vec<String> = (0..100)
        .map(|y| {
            (0..204)
                .map(|x| if x % 4 == 0 && y % 2 == 0 { '@' } else { '.' })
                .collect()
        })
        .collect();
    let text = format!(
        "type octile\nheight 100\nwidth 204\nmap\n{}\n",
        rows.join("\n")
    );
    let path = dir.join("dots.map");
    std::fs::write(&path, text).unwrap();
    let half = ImportOptions {
        cell_size: Some(0.5),
        ..ImportOptions::default()
    };
    let e = import_file(&path, &half).unwrap_err().to_string();
    assert!(e.contains("2550 rectangles (10200 vertices)"), "{e}");
    assert!(e.contains("--resolution-scale"), "{e}");
    let coarse = ImportOptions { coarsen: 2, ..half };
    let f: MapFile = import_file(&path, &coarse).unwrap().file;
    // Every other coarse column is wall from top to bottom.
    assert!(f.obstacles.len() <= 52, "{}", f.obstacles.len());
}

#[test]
fn the_cli_imports_and_exports_by_name() {
    let dir = folder("cli");
    let yaml = room().write(&dir, "lab", "png", [-3.0, -2.0]);
    let maps = dir.join("maps");
    let import = |force| {
        cli::run(&MapCommand::Import(ImportArgs {
            file: yaml.clone(),
            out: Some(maps.join("lab.json")),
            name: None,
            resolution_scale: 1,
            cell_size: None,
            keep_extent: false,
            force,
        }))
    };
    let report = import(false).unwrap();
    assert!(report.contains("--origin=-2.5,-1.5,0"), "{report}");
    let text = std::fs::read_to_string(maps.join("lab.json")).unwrap();
    let def = lasertag::maps::parse(&text).unwrap();
    assert_eq!((def.width, def.height), (10.0, 7.5));
    let e = import(false).unwrap_err().to_string();
    assert!(e.contains("exists; give --force"), "{e}");
    assert!(import(true).is_ok());

    let out = dir.join("ros");
    let report = cli::run(&MapCommand::Export(ExportArgs {
        map: "lab".into(),
        out: out.clone(),
        resolution: 0.25,
        origin: Some([-2.5, -1.5, 0.0]),
        maps: maps.clone(),
    }))
    .unwrap();
    assert!(report.contains("42 × 32 pixels"), "{report}");
    let yaml_text = std::fs::read_to_string(out.join("lab.yaml")).unwrap();
    assert!(
        yaml_text.contains("origin: [-2.75, -1.75, 0]"),
        "{yaml_text}"
    );
    let e = cli::run(&MapCommand::Export(ExportArgs {
        map: "nowhere".into(),
        out,
        resolution: 0.25,
        origin: None,
        maps,
    }))
    .unwrap_err()
    .to_string();
    assert!(e.contains("no map named \"nowhere\""), "{e}");
}

#[test]
fn the_binary_runs_map_import_and_export() {
    let dir = folder("binary");
    std::fs::write(
        dir.join("grid.map"),
        "type octile\nheight 6\nwidth 12\nmap\n............\n............\n..@@........\n\
         ............\n............\n............\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_lasertag");
    let run = |args: &[&str]| {
        std::process::Command::new(bin)
            .args(args)
            .current_dir(&dir)
            .env_remove("LASERTAG_MAPS")
            .output()
            .unwrap()
    };
    let out = run(&["map", "import", "grid.map", "--cell-size", "0.5"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("maps/grid.json").is_file());
    let out = run(&[
        "map",
        "export",
        "grid",
        "--out",
        "ros",
        "--resolution",
        "0.1",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("ros/grid.yaml").is_file() && dir.join("ros/grid.pgm").is_file());
    let out = run(&["map", "import", "missing.map"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.map"));
}
