//! `relume-editor [GRAPH.ron] [--run] [--screenshot OUT.png] [--cache DIR]`

use relume_editor::screenshot::ScreenshotJob;
use relume_editor::EditorApp;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;
use std::time::Duration;

const USAGE: &str =
    "usage: relume-editor [GRAPH.ron] [--run] [--select NODE] [--screenshot OUT.png] [--timeout SECONDS] [--cache DIR | --no-disk-cache]

  GRAPH.ron          graph file to open (a new graph when left out)
  --run              run the graph once it is open
  --select NODE      select a node (its parameters show in the properties panel)
  --screenshot OUT   run, wait for the image, save an in-app screenshot to OUT and exit
                     (exit code 0 when the viewer shows a picture, 2 when it looks blank)
  --timeout S        give up the screenshot after S seconds (default 600)
  --cache DIR        disk cache folder, shared with `relume run` (default: $RELUME_CACHE or .relume-cache)
  --no-disk-cache    keep results in memory only";

struct Args {
    graph: Option<PathBuf>,
    run: bool,
    screenshot: Option<PathBuf>,
    timeout: u64,
    cache: Option<PathBuf>,
    select: Option<String>,
    no_disk_cache: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args { graph: None, run: false, screenshot: None, timeout: 600, cache: None, select: None, no_disk_cache: false };
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
    if let Some(id) = &args.select {
        if app.doc.graph.node(id).is_none() {
            eprintln!("relume-editor: no node \"{id}\" to select");
            std::process::exit(64);
        }
        app.view.rebuild(&app.doc.graph, app.doc.revision);
        app.view.select(id);
    }
    let exit = Arc::new(AtomicI32::new(0));
    if let Some(out) = &args.screenshot {
        app.screenshot = Some(ScreenshotJob::new(out.clone(), Duration::from_secs(args.timeout), exit.clone()));
    }
    if args.run || args.screenshot.is_some() {
        app.run();
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size([1400.0, 860.0]).with_title("relume editor"),
        ..Default::default()
    };
    let result = eframe::run_native("relume editor", options, Box::new(|_cc| Ok(Box::new(Window(app)))));
    if let Err(e) = result {
        eprintln!("relume-editor: cannot open a window: {e}");
        std::process::exit(5);
    }
    std::process::exit(exit.load(Ordering::SeqCst));
}

struct Window(EditorApp);

impl eframe::App for Window {
    fn update(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        self.0.ui(ctx);
    }
}
