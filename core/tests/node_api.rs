//! The node API end to end: `derive(Params)` and `params!` (with test values and flattened
//! groups),
//! `derive(ParamEnum)`, ports from `run`'s signature or from `inputs!`/`outputs!`, `#[node]`
//! with its declared metrics, and parameter values normalised once into one cache key.

use relume_core::{
    inputs, node, outputs, Engine, Graph, NodeError, ParamEnum, ParamKind, ParamValue, Params, PortValue, Registry, RunCtx, RunOptions,
};
use std::path::PathBuf;

/// A number on an edge.
#[derive(Clone, Debug, PartialEq)]
pub struct Num(f64);

impl PortValue for Num {
    const NAME: &'static str = "Num";
    const COLOR: [u8; 3] = [1, 2, 3];
    fn byte_size(&self) -> usize {
        8
    }
    fn encode(&self) -> Vec<u8> {
        self.0.to_le_bytes().to_vec()
    }
    fn decode(b: &[u8]) -> Option<Self> {
        Some(Num(f64::from_le_bytes(b.try_into().ok()?)))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, ParamEnum)]
pub enum Op {
    Add,
    Mul,
}

/// Emits a constant.
/// Second line of the doc.
#[derive(Params)]
pub struct Source {
    /// the value
    #[param(default = 1.0, range = -10.0..=10.0, unit = "W")]
    pub value: f64,
}

outputs!(pub SourceOut { out: Num });

#[node(category = "test")]
impl Source {
    fn run(&self, _: (), _cx: &RunCtx) -> Result<SourceOut, NodeError> {
        Ok(SourceOut { out: Num(self.value) })
    }
}

/// Combines two numbers with every kind of parameter.
#[derive(Params)]
pub struct Apply {
    /// how to combine
    #[param(default = Add)]
    pub op: Op,
    /// a scale
    #[param(default = 2.0, range = 0.0..=64.0, unit = "px")]
    pub sigma: f32,
    /// a count
    #[param(default = 3, range = 1..=10)]
    pub n: u32,
    /// a switch
    #[param(default = true)]
    pub on: bool,
    /// a label
    #[param(default = "x")]
    pub label: String,
    /// a colour
    #[param(rgb, default = (1.0, 0.5, 0.25), range = 0.0..=1.0)]
    pub colour: [f32; 3],
    /// a position
    #[param(default = (0.0, -1.0, 2.0))]
    pub at: [f32; 3],
    /// a file written
    #[param(output, default = "out.txt")]
    pub target: PathBuf,
}

inputs!(pub ApplyIn { a: Num, b: Num });
outputs!(pub ApplyOut { out: Num, twice: Num });

#[node(category = "test", version = 3)]
impl Apply {
    fn run(&self, i: ApplyIn, cx: &RunCtx) -> Result<ApplyOut, NodeError> {
        let v = match self.op {
            Op::Add => i.a.0 + i.b.0,
            Op::Mul => i.a.0 * i.b.0,
        } * self.sigma as f64;
        let parts = cx.par_map(self.n as usize, |k| k as f64)?;
        let v = v + parts.iter().sum::<f64>() * 0.0;
        Ok(ApplyOut { out: Num(v), twice: Num(2.0 * v) })
    }
}

/// Rounds down to a whole number (two inputs, one output).
#[derive(Params)]
pub struct Floor {}

inputs!(pub FloorIn { a: Num });
outputs!(pub FloorOut { out: Num });

#[node(category = "test")]
impl Floor {
    fn run(&self, i: FloorIn, _cx: &RunCtx) -> Result<FloorOut, NodeError> {
        Ok(FloorOut { out: Num(i.a.0.floor()) })
    }
}

/// `Floor` with its output fingerprinted by the run's key.
#[derive(Params)]
pub struct KeyedFloor {}

#[node(category = "test", caching = Keyed)]
impl KeyedFloor {
    fn run(&self, i: FloorIn, _cx: &RunCtx) -> Result<FloorOut, NodeError> {
        Ok(FloorOut { out: Num(i.a.0.floor()) })
    }
}

fn registry() -> Registry {
    let mut r = Registry::new();
    r.add::<Source>().add::<Apply>().add::<Floor>().add::<KeyedFloor>();
    r
}

#[test]
fn derive_params_builds_the_schema_from_the_fields() {
    use relume_core::{Documented, Node};
    let s = Apply::schema();
    let names: Vec<_> = s.0.iter().map(|p| p.name).collect();
    assert_eq!(names, ["op", "sigma", "n", "on", "label", "colour", "at", "target"]);
    assert_eq!(s.get("op").unwrap().kind, ParamKind::Enum(&["Add", "Mul"]));
    assert_eq!(s.get("op").unwrap().default, Some(ParamValue::Ident("Add".into())));
    assert_eq!(s.get("sigma").unwrap().kind, ParamKind::Float { min: 0.0, max: 64.0 });
    assert_eq!((s.get("sigma").unwrap().unit, s.get("sigma").unwrap().help), ("px", "a scale"));
    assert_eq!(s.get("n").unwrap().kind, ParamKind::Int { min: 1, max: 10 });
    assert_eq!(s.get("colour").unwrap().kind, ParamKind::Rgb { min: 0.0, max: 1.0 });
    assert_eq!(s.get("at").unwrap().kind, ParamKind::Vec3);
    assert_eq!(s.get("target").unwrap().kind, ParamKind::OutputFile);
    assert_eq!(Source::schema().get("value").unwrap().default, Some(ParamValue::Float(1.0)));
    assert_eq!(Source::DOC, " Emits a constant.\n Second line of the doc.");
    assert_eq!((Apply::KIND, Apply::VERSION, Apply::CATEGORY), ("Apply", 3, "test"));
    let reg = registry();
    let apply = reg.node("Apply").unwrap();
    assert_eq!(apply.doc(), "Combines two numbers with every kind of parameter.");
    let ports = apply.ports();
    assert_eq!(ports.inputs.iter().map(|p| p.name).collect::<Vec<_>>(), ["a", "b"]);
    assert_eq!(ports.outputs.iter().map(|p| (p.name, p.ty.name)).collect::<Vec<_>>(), [("out", "Num"), ("twice", "Num")]);
}

#[test]
fn enum_variants_are_listed_once_and_unknown_names_are_refused() {
    assert_eq!(Op::VARIANTS, ["Add", "Mul"]);
    assert_eq!(Op::from_name("Mul"), Some(Op::Mul));
    assert_eq!(Op::from_name("Div"), None, "no fallback to a default variant");
    assert_eq!(Op::Mul.name(), "Mul");
    let err = Graph::parse(r#"(version: 1, nodes: { "a": (kind: "Source", params: ()), "x": (kind: "Apply", params: (op: Div)) })"#, None)
        .unwrap()
        .validate(&registry())
        .unwrap_err()
        .to_string();
    assert!(err.contains("`Div` is not one of Add, Mul"), "{err}");
}

/// Two sources, `a` with value `a`, `b` with its default 1, into node "x" of `kind` with
/// `params`; the graph outputs are x's ports `outputs`.
fn two_sources_into(a: f64, kind: &str, params: &str, outputs: [&str; 2]) -> Graph {
    let [o1, o2] = outputs;
    Graph::parse(
        &format!(
            r#"(version: 1, nodes: {{ "a": (kind: "Source", params: (value: {a})), "b": (kind: "Source", params: ()),
               "x": (kind: "{kind}", params: ({params})) }},
               edges: [("a.out", "x.a"), ("b.out", "x.b")], outputs: {{ "{o1}": "x.{o1}", "{o2}": "x.{o2}" }})"#
        ),
        None,
    )
    .unwrap()
}

fn graph(apply_params: &str) -> Graph {
    two_sources_into(2.0, "Apply", apply_params, ["out", "twice"])
}

fn key_of(g: &Graph) -> String {
    let e = Engine::new(registry());
    let r = e.run(g, &RunOptions::default()).unwrap();
    r.report.node("x").unwrap().key.clone()
}

#[test]
fn typed_ports_carry_values_through_a_run() {
    let r = Engine::new(registry()).run(&graph(""), &RunOptions::default()).unwrap();
    assert_eq!(r.output("out").unwrap().get::<Num>(), Some(&Num(6.0)), "(2 + 1) × 2");
    assert_eq!(r.output("twice").unwrap().get::<Num>(), Some(&Num(12.0)));
}

#[test]
fn int_and_float_spellings_defaults_and_set_give_one_cache_key() {
    let default = key_of(&graph(""));
    assert_eq!(key_of(&graph("sigma: 2")), default, "an integer for a float parameter");
    assert_eq!(key_of(&graph("sigma: 2.0")), default);
    assert_eq!(key_of(&graph("sigma: 2.0, op: Add, n: 3, colour: (1, 0.5, 0.25)")), default, "defaults written out");
    assert_eq!(key_of(&graph(r#"op: "Add""#)), default, "an enum as a string");
    let mut g = graph("sigma: 3");
    g.set_param_text(&registry(), "x.sigma", "2").unwrap();
    assert_eq!(key_of(&g), default, "--set of the same value");
    let mut g = graph("at: (0, -1, 2)");
    g.set_param_text(&registry(), "x.at", "(0.0, -1.0, 2.0)").unwrap();
    assert_eq!(key_of(&g), default, "a vec3 with integers");
    assert_ne!(key_of(&graph("sigma: 2.5")).as_str(), default, "a different value is a different key");
    // Upstream: `value: 2` and `value: 2.0` give the same input fingerprint.
    let a = graph("");
    let mut b = graph("");
    b.set_param_text(&registry(), "a.value", "2.0").unwrap();
    assert_eq!(key_of(&a), key_of(&b));
}

#[test]
fn a_rerun_that_reproduces_its_bytes_cuts_off_downstream_unless_its_node_is_keyed() {
    let floor_graph = |kind: &str, value: f64| {
        Graph::parse(
            &format!(
                r#"(version: 1, nodes: {{ "a": (kind: "Source", params: (value: {value:?})), "b": (kind: "Source", params: ()),
                   "f": (kind: "{kind}", params: ()), "x": (kind: "Apply", params: ()) }},
                   edges: [("a.out", "f.a"), ("f.out", "x.a"), ("b.out", "x.b")], outputs: {{ "out": "x.out" }})"#
            ),
            None,
        )
        .unwrap()
    };
    for (kind, keyed) in [("Floor", false), ("KeyedFloor", true)] {
        let e = Engine::new(registry());
        let first = e.run(&floor_graph(kind, 2.25), &RunOptions::default()).unwrap();
        // 2.75 floors to the same 2: `f` re-runs and gives the same bytes.
        let second = e.run(&floor_graph(kind, 2.75), &RunOptions::default()).unwrap();
        assert_eq!(second.output("out").unwrap().get::<Num>(), Some(&Num(6.0)));
        let ran = second.report.ran_ids();
        assert!(ran.contains(&"f"), "{kind}: {ran:?}");
        // A content fingerprint sees the same output and leaves `x` alone; a key fingerprint
        // sees a new run.
        assert_eq!(ran.contains(&"x"), keyed, "{kind}: {ran:?}");
        let fp = |r: &relume_core::RunResult| r.report.node("x").unwrap().key.clone();
        assert_eq!(fp(&first) != fp(&second), keyed, "{kind}");
        // The same run in a fresh engine gives the same fingerprints either way.
        let again = Engine::new(registry()).run(&floor_graph(kind, 2.75), &RunOptions::default()).unwrap();
        assert_eq!(fp(&again), fp(&second), "{kind}");
    }
}

/// A group of parameters two nodes share, declared once.
#[derive(Clone, Copy, Debug, PartialEq, Params)]
pub struct Counts {
    /// samples
    #[param(default = 16, range = 1..=1024, test = 2)]
    pub spp: u32,
    /// random seed
    #[param(default = 0, range = 0..=99)]
    pub seed: u64,
}

/// Splits a number into its whole and fractional parts, scaled (ports from the signature).
#[derive(Params)]
pub struct Split {
    /// a scale
    #[param(default = 1.0, range = 0.0..=10.0, test = 0.5)]
    pub scale: f64,
    /// the shared group
    #[param(flatten)]
    pub counts: Counts,
}

#[node(category = "test", metrics = ["whole"], outputs = [whole, frac])]
impl Split {
    fn run(&self, a: &Num, b: &Num, cx: &RunCtx) -> Result<(Num, Num), NodeError> {
        let v = (a.0 + b.0) * self.scale + self.counts.spp as f64 * 0.0;
        cx.metric("whole", v.floor());
        Ok((Num(v.floor()), Num(v - v.floor())))
    }
}

/// Records a metric it does not declare.
#[derive(Params)]
pub struct Undeclared {}

#[node(category = "test", metrics = ["declared"], outputs = [out])]
impl Undeclared {
    fn run(&self, cx: &RunCtx) -> Result<Num, NodeError> {
        cx.metric("declared", 1.0);
        cx.metric("other", 2.0);
        Ok(Num(0.0))
    }
}

fn split_graph(params: &str) -> Graph {
    two_sources_into(2.25, "Split", params, ["whole", "frac"])
}

#[test]
fn ports_come_from_runs_signature_and_outputs_from_its_result() {
    let mut reg = registry();
    reg.add::<Split>();
    let ports = reg.node("Split").unwrap().ports();
    let names = |p: &[relume_core::PortDecl]| p.iter().map(|d| (d.name.to_string(), d.ty.name)).collect::<Vec<_>>();
    assert_eq!(names(&ports.inputs), [("a".to_string(), "Num"), ("b".to_string(), "Num")]);
    assert_eq!(names(&ports.outputs), [("whole".to_string(), "Num"), ("frac".to_string(), "Num")]);
    let r = Engine::new(reg).run(&split_graph("scale: 2"), &RunOptions::default()).unwrap();
    assert_eq!(r.output("whole").unwrap().get::<Num>(), Some(&Num(6.0)), "(2.25 + 1) × 2 = 6.5");
    assert_eq!(r.output("frac").unwrap().get::<Num>(), Some(&Num(0.5)));
    assert_eq!(r.report.node("x").unwrap().metrics["whole"], 6.0);
    // The written function stays callable with plain references.
    let s = Split { scale: 1.0, counts: Counts { spp: 1, seed: 0 } };
    let cancel = relume_core::CancelToken::new();
    let (w, f) = s.run_ports(&Num(1.5), &Num(1.0), &RunCtx::new("s", &cancel, None)).unwrap();
    assert_eq!((w, f), (Num(2.0), Num(0.5)));
}

#[test]
fn a_flattened_group_lists_its_parameters_as_the_nodes_own() {
    let s = Split::schema();
    let names: Vec<&str> = s.0.iter().map(|p| p.name).collect();
    assert_eq!(names, ["scale", "spp", "seed"]);
    let mut reg = registry();
    reg.add::<Split>();
    let mut g = split_graph("spp: 5, seed: 7");
    g.validate(&reg).unwrap();
    assert_eq!(g.node("x").unwrap().param("spp"), Some(&ParamValue::Int(5)));
    let err = split_graph("spp: 0").validate(&reg).unwrap_err().to_string();
    assert!(err.contains("spp") && err.contains("out of range [1, 1024]"), "{err}");
    // Test values come from both the node's fields and the group's.
    g.shrink_to_test_size(&reg).unwrap();
    let s = g.node("x").unwrap();
    assert_eq!(
        (s.param("scale"), s.param("spp"), s.param("seed")),
        (Some(&ParamValue::Float(0.5)), Some(&ParamValue::Int(2)), Some(&ParamValue::Int(7)))
    );
}

#[test]
#[should_panic(expected = "declares the parameter `spp` twice")]
fn a_parameter_declared_twice_through_a_group_is_refused_at_registration() {
    /// Repeats the group's `spp`.
    #[derive(Params)]
    #[allow(dead_code)]
    pub struct Twice {
        /// again
        #[param(default = 1, range = 1..=2)]
        pub spp: u32,
        /// the group
        #[param(flatten)]
        pub counts: Counts,
    }
    #[node(category = "test", outputs = [out])]
    impl Twice {
        fn run(&self, _cx: &RunCtx) -> Result<Num, NodeError> {
            Ok(Num(0.0))
        }
    }
    Registry::new().add::<Twice>();
}

#[test]
fn a_metric_the_node_does_not_declare_fails_the_run() {
    let mut reg = Registry::new();
    reg.add::<Undeclared>();
    assert_eq!(reg.node("Undeclared").unwrap().metrics(), ["declared"]);
    let g = Graph::parse(r#"(version: 1, nodes: { "u": (kind: "Undeclared", params: ()) }, edges: [], outputs: { "o": "u.out" })"#, None)
        .unwrap();
    let err = Engine::new(reg).run(&g, &RunOptions::default()).err().unwrap().to_string();
    assert!(err.contains("recorded the metric `other`, which it does not declare") && err.contains("lists: declared"), "{err}");
}

relume_core::params! {
    /// Combines two numbers with every kind of parameter.
    #[derive(Clone, Debug)]
    pub struct ApplyOneLine {
        /// how to combine
        pub op: Op = Add;
        /// a scale
        pub sigma: f32 = 2.0, range = 0.0..=64.0, unit = "px";
        /// a count
        pub n: u32 = 3, range = 1..=10;
        /// a switch
        pub on: bool = true;
        /// a label
        pub label: String = "x";
        /// a colour
        pub colour: [f32; 3] = (1.0, 0.5, 0.25), rgb, range = 0.0..=1.0;
        /// a position
        pub at: [f32; 3] = (0.0, -1.0, 2.0);
        /// a file written
        pub target: PathBuf = "out.txt", output;
    }
}

relume_core::params! {
    /// `Split`'s parameters, one line each; `spp` is required here.
    pub struct SplitOneLine {
        /// a scale
        pub scale: f64 = 1.0, range = 0.0..=10.0, test = 0.5;
        /// the shared group
        pub counts: Counts, flatten;
        /// required: no default
        pub spp_too: u32, range = 1..=4
    }
}

relume_core::params! {
    /// No parameters.
    pub struct NoneOneLine;
}

#[test]
fn params_block_declares_the_same_schema_as_the_derive() {
    use relume_core::Documented;
    assert_eq!(ApplyOneLine::schema().0, Apply::schema().0);
    assert_eq!(ApplyOneLine::DOC, Apply::DOC);
    // The struct's own attributes pass through.
    let v = relume_core::ParamValues::resolve(&ApplyOneLine::schema(), &[], std::path::Path::new(".")).unwrap();
    let p = ApplyOneLine::from_values(&v).unwrap().clone();
    assert_eq!((p.op, p.sigma, p.n, p.on, p.label.as_str(), p.colour), (Op::Add, 2.0, 3, true, "x", [1.0, 0.5, 0.25]));
    // A flattened group, a test value, a required field, and a last field without `;`.
    let s = SplitOneLine::schema();
    let names: Vec<&str> = s.0.iter().map(|p| p.name).collect();
    assert_eq!(names, ["scale", "spp", "seed", "spp_too"]);
    assert_eq!(s.0[0].test, Some(ParamValue::Float(0.5)));
    assert_eq!(s.0[3].default, None);
    assert_eq!(s.0[3].kind, ParamKind::Int { min: 1, max: 4 });
    assert!(NoneOneLine::schema().0.is_empty());
    assert_eq!(NoneOneLine::DOC, " No parameters.");
}
