//! `relume-editor [GRAPH.ron] [--run] [--screenshot OUT.png] [--drive NODE.PARAM=FROM:TO] [--record OUT.csv] [--cache DIR]`

use relume_editor::drive::DriveJob;
use relume_editor::screenshot::ScreenshotJob;
use relume_editor::EditorApp;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;
use std::time::Duration;

const USAGE: &str = "usage: relume-editor [GRAPH.ron] [--run] [--select NODE] [--screenshot OUT.png [--graph-only]] [--timeout SECONDS]
                     [--set NODE.PARAM=VALUE ...] [--drive NODE.PARAM=FROM:TO [--drive-seconds S] [--drive-strip PNG]]
                     [--record OUT.csv]
                     [--cache DIR | --no-disk-cache]

  GRAPH.ron          graph file to open (a new graph when left out)
  --run              run the graph once it is open
  --set N.P=VALUE    set a parameter after opening, as `relume run --set` does (an undoable edit)
  --select NODE      select a node (its parameters show in the properties panel)
  --screenshot OUT   run, wait for the image, save an in-app screenshot to OUT and exit
                     (exit code 0 when the viewer shows a picture, 2 when it looks blank)
  --graph-only       save only the node graph's part of the screenshot, cropped to its nodes;
                     the graph is not run
  --window WxH       the window's size in points (default 1400x860)
  --timeout S        give up the screenshot or the drive after S seconds without an image (default 600)
  --drive N.P=A:B    once the image shows, set number parameter P of node N every frame from A to B
                     and back, as a slider drag does, recording each frame; then run the same edit
                     through the engine alone; print both rates and exit
  --drive-seconds S  how long the drive lasts (default 10)
  --drive-strip PNG  also screenshot the viewer four times on the drive's way out, side by side
                     in PNG (each screenshot costs a frame: measure without it)
  --record OUT.csv   write every frame's time and each new image's latency to OUT.csv (with
                     --drive: during the drive; alone: from start to close)
  --cache DIR        disk cache folder, shared with `relume run` (default: $RELUME_CACHE or .relume-cache)
  --no-disk-cache    keep results in memory only
  --viewer-only      open in the viewer-only layout (F11 toggles it): the viewer in the centre,
                     the parameters beside it, no palette or node graph";

struct Args {
    graph: Option<PathBuf>,
    run: bool,
    screenshot: Option<PathBuf>,
    graph_only: bool,
    window: [f32; 2],
    timeout: u64,
    cache: Option<PathBuf>,
    select: Option<String>,
    no_disk_cache: bool,
    drive: Option<String>,
    drive_seconds: f64,
    sets: Vec<String>,
    strip: Option<PathBuf>,
    record: Option<PathBuf>,
    viewer_only: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        graph: None,
        run: false,
        screenshot: None,
        timeout: 600,
        cache: None,
        select: None,
        no_disk_cache: false,
        drive: None,
        drive_seconds: 10.0,
        sets: Vec::new(),
        strip: None,
        record: None,
        viewer_only: false,
        graph_only: false,
        window: [1400.0, 860.0],
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--run" => a.run = true,
            "--screenshot" => a.screenshot = Some(value("--screenshot")?.into()),
            "--timeout" => a.timeout = value("--timeout")?.parse().map_err(|_| "--timeout needs a number of seconds")?,
            "--cache" => a.cache = Some(value("--cache")?.into()),
            "--no-disk-cache" => a.no_disk_cache = true,
            "--select" => a.select = Some(value("--select")?),
            "--drive" => a.drive = Some(value("--drive")?),
            "--set" => a.sets.push(value("--set")?),
            "--drive-strip" => a.strip = Some(value("--drive-strip")?.into()),
            "--drive-seconds" => {
                a.drive_seconds = value("--drive-seconds")?.parse().map_err(|_| "--drive-seconds needs a number of seconds")?
            }
            "--record" => a.record = Some(value("--record")?.into()),
            "--viewer-only" => a.viewer_only = true,
            "--graph-only" => a.graph_only = true,
            "--window" => {
                let v = value("--window")?;
                let size = v.split_once('x').and_then(|(w, h)| Some([w.parse::<f32>().ok()?, h.parse::<f32>().ok()?]));
                a.window = size.filter(|s| s.iter().all(|x| (200.0..=8192.0).contains(x))).ok_or("--window needs WxH, each 200 to 8192")?;
            }
            "-h" | "--help" => return Err(String::new()),
            s if s.starts_with('-') => return Err(format!("unknown option {s}")),
            s => a.graph = Some(s.into()),
        }
    }
    Ok(a)
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(m) => {
            if !m.is_empty() {
                eprintln!("relume-editor: {m}");
            }
            eprintln!("{USAGE}");
            std::process::exit(if m.is_empty() { 0 } else { 64 });
        }
    };
    let registry = relume_editor::registry();
    let mut engine = relume_core::Engine::new(registry.clone());
    if !args.no_disk_cache {
        let dir = args.cache.clone().or_else(|| std::env::var_os("RELUME_CACHE").map(PathBuf::from)).unwrap_or(".relume-cache".into());
        engine = engine.with_disk_cache(dir);
    }
    let mut app = EditorApp::new(registry, engine);
    if let Some(g) = &args.graph {
        if let Err(e) = app.open(g) {
            eprintln!("relume-editor: {e}");
            std::process::exit(1);
        }
    }
    for set in &args.sets {
        if let Err(e) = app.set_text(set) {
            eprintln!("relume-editor: --set {set}: {e}");
            std::process::exit(64);
        }
    }
    if let Some(id) = &args.select {
        if app.doc.graph.node(id).is_none() {
            eprintln!("relume-editor: no node \"{id}\" to select");
            std::process::exit(64);
        }
        app.view.rebuild(&app.doc.graph, app.doc.revision);
        app.view.select(id);
    }
    app.viewer_only = args.viewer_only;
    let exit = Arc::new(AtomicI32::new(0));
    if let Some(out) = &args.screenshot {
        let job = ScreenshotJob::new(out.clone(), Duration::from_secs(args.timeout), exit.clone());
        app.screenshot = Some(if args.graph_only { job.graph_only() } else { job });
    }
    let drive = match &args.drive {
        Some(spec) => {
            let record = args.record.clone().unwrap_or_else(|| "frames.csv".into());
            let job =
                DriveJob::parse(spec, args.drive_seconds, record, Duration::from_secs(args.timeout)).and_then(|j| j.check(&app).map(|_| j));
            match job {
                Ok(j) => Some(match &args.strip {
                    Some(p) => j.with_strip(p.clone()),
                    None => j,
                }),
                Err(e) => {
                    eprintln!("relume-editor: {e}");
                    std::process::exit(64);
                }
            }
        }
        None => {
            if let Some(path) = &args.record {
                app.stats.record_path = Some(path.clone());
                app.stats.start_recording();
            }
            None
        }
    };
    if args.run || (args.screenshot.is_some() && !args.graph_only) || drive.is_some() {
        app.run();
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size(args.window).with_title("relume editor"),
        ..Default::default()
    };
    let window = Window { app, drive, exit: exit.clone() };
    let result = eframe::run_native("relume editor", options, Box::new(|_cc| Ok(Box::new(window))));
    if let Err(e) = result {
        eprintln!("relume-editor: cannot open a window: {e}");
        std::process::exit(5);
    }
    std::process::exit(exit.load(Ordering::SeqCst));
}

struct Window {
    app: EditorApp,
    drive: Option<DriveJob>,
    exit: Arc<AtomicI32>,
}

impl eframe::App for Window {
    fn update(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        self.app.pace_frame();
        self.app.ui(ctx);
        if let Some(d) = &mut self.drive {
            d.frame(&mut self.app, ctx);
            if d.done {
                self.exit.store(d.exit, Ordering::SeqCst);
            }
        }
    }

    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        relume_editor::panels::panel_clear(visuals)
    }

    fn on_exit(&mut self, _gl: Option<&eframe::glow::Context>) {
        // A recording started with --record alone is written when the window closes.
        if self.app.stats.is_recording() {
            self.app.toggle_recording();
            println!("{}", self.app.status);
        }
    }
}
