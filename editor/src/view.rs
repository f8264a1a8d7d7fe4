//! The node-graph widget (egui_node_graph2) as a view of the core graph: node widgets with
//! typed, coloured ports, state badges and doc tooltips; the widget's edits are turned back
//! into edits of the document, and the widget is rebuilt from the document after undo, redo
//! or loading.

use crate::edit;
use crate::runner::NodeState;
use egui::{Color32, Pos2, Vec2};
use egui_node_graph2 as eng;
use relume_core::graph::PortRef;
use relume_core::{Graph, Registry};
use std::borrow::Cow;
use std::collections::HashMap;

/// Per-node data in the widget: the core id (the node's title) and kind (the small label
/// beside it).
#[derive(Clone, Debug)]
pub struct NodeData {
    pub id: String,
    pub kind: &'static str,
}

/// A port's type: its registered name and colour. Ports connect only when these are equal.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PortType {
    pub name: &'static str,
    pub color: [u8; 3],
}

/// Ports carry no inline values (parameters live in the properties panel).
#[derive(Clone, Debug, Default)]
pub struct NoValue;

/// An entry of the node finder: a registered kind.
#[derive(Clone, Debug)]
pub struct Template {
    pub kind: &'static str,
    pub category: &'static str,
}

#[derive(Clone, Debug)]
pub enum Response {}
impl eng::UserResponseTrait for Response {}

/// What node widgets read while drawing.
pub struct UserState {
    pub registry: Registry,
    pub states: HashMap<String, NodeState>,
}

pub type EditorState = eng::GraphEditorState<NodeData, PortType, NoValue, Template, UserState>;
pub type NodeResponse = eng::NodeResponse<Response, NodeData>;

impl eng::DataTypeTrait<UserState> for PortType {
    fn data_type_color(&self, _: &mut UserState) -> Color32 {
        Color32::from_rgb(self.color[0], self.color[1], self.color[2])
    }
    fn name(&self) -> Cow<'_, str> {
        Cow::Borrowed(self.name)
    }
}

impl eng::WidgetValueTrait for NoValue {
    type Response = Response;
    type UserState = UserState;
    type NodeData = NodeData;
    fn value_widget(&mut self, name: &str, _: eng::NodeId, ui: &mut egui::Ui, _: &mut UserState, _: &NodeData) -> Vec<Response> {
        ui.label(name);
        Vec::new()
    }
}

/// Colour of a node state (badge and title bar).
pub fn state_color(s: &NodeState) -> Color32 {
    match s {
        NodeState::Cached => Color32::from_rgb(90, 160, 90),
        NodeState::Stale => Color32::from_rgb(200, 150, 60),
        NodeState::Unused => Color32::from_rgb(120, 120, 120),
        NodeState::Running(_) => Color32::from_rgb(80, 140, 220),
        NodeState::Done(_) => Color32::from_rgb(110, 200, 110),
        NodeState::Failed(_) => Color32::from_rgb(220, 80, 80),
    }
}

impl eng::NodeDataTrait for NodeData {
    type Response = Response;
    type UserState = UserState;
    type DataType = PortType;
    type ValueType = NoValue;

    fn top_bar_ui(
        &self,
        ui: &mut egui::Ui,
        _: eng::NodeId,
        _: &eng::Graph<NodeData, PortType, NoValue>,
        state: &mut UserState,
    ) -> Vec<NodeResponse> {
        let doc = state.registry.node(self.kind).map(|k| k.doc().to_string()).unwrap_or_default();
        ui.label(egui::RichText::new(self.kind).small().weak()).on_hover_text(doc);
        Vec::new()
    }

    fn bottom_ui(
        &self,
        ui: &mut egui::Ui,
        _: eng::NodeId,
        _: &eng::Graph<NodeData, PortType, NoValue>,
        state: &mut UserState,
    ) -> Vec<NodeResponse> {
        if let Some(s) = state.states.get(&self.id) {
            match s {
                NodeState::Running(f) => {
                    ui.add(egui::ProgressBar::new(*f).desired_width(140.0).show_percentage());
                }
                NodeState::Failed(m) => {
                    ui.colored_label(state_color(s), "failed").on_hover_text(m);
                }
                _ => {
                    ui.colored_label(state_color(s), s.label());
                }
            }
        }
        Vec::new()
    }

    fn titlebar_color(
        &self,
        _: &egui::Ui,
        _: eng::NodeId,
        _: &eng::Graph<NodeData, PortType, NoValue>,
        state: &mut UserState,
    ) -> Option<Color32> {
        state.states.get(&self.id).map(|s| state_color(s).gamma_multiply(0.45))
    }
}

impl eng::NodeTemplateTrait for Template {
    type NodeData = NodeData;
    type DataType = PortType;
    type ValueType = NoValue;
    type UserState = UserState;
    type CategoryType = &'static str;

    fn node_finder_label(&self, _: &mut UserState) -> Cow<'_, str> {
        Cow::Borrowed(self.kind)
    }
    fn node_finder_categories(&self, _: &mut UserState) -> Vec<&'static str> {
        vec![self.category]
    }
    fn node_graph_label(&self, _: &mut UserState) -> String {
        self.kind.to_string()
    }
    fn user_data(&self, _: &mut UserState) -> NodeData {
        NodeData { id: String::new(), kind: self.kind }
    }
    fn build_node(&self, graph: &mut eng::Graph<NodeData, PortType, NoValue>, state: &mut UserState, node: eng::NodeId) {
        add_ports(graph, &state.registry, node, self.kind);
    }
}

fn add_ports(graph: &mut eng::Graph<NodeData, PortType, NoValue>, reg: &Registry, node: eng::NodeId, kind: &str) {
    let Some(k) = reg.node(kind) else { return };
    for p in &k.ports().inputs {
        let ty = PortType { name: p.ty.name, color: p.ty.color };
        graph.add_input_param(node, p.name.to_string(), ty, NoValue, eng::InputParamKind::ConnectionOnly, true);
    }
    for p in &k.ports().outputs {
        graph.add_output_param(node, p.name.to_string(), PortType { name: p.ty.name, color: p.ty.color });
    }
}

/// Every registered kind, for the node finder.
pub struct AllKinds(pub Vec<Template>);

impl eng::NodeTemplateIter for &AllKinds {
    type Item = Template;
    fn all_kinds(&self) -> Vec<Template> {
        self.0.clone()
    }
}

impl AllKinds {
    pub fn new(reg: &Registry) -> Self {
        AllKinds(reg.nodes().map(|n| Template { kind: n.kind(), category: n.category() }).collect())
    }
}

/// Maps layout coordinates (the file's) to the widget's, which it scales itself when zooming:
/// widget = layout × scale + offset.
#[derive(Clone, Copy, Debug)]
pub struct Transform {
    pub scale: f32,
    pub offset: Vec2,
}

impl Transform {
    pub fn to_widget(&self, p: [f64; 2]) -> Pos2 {
        Pos2::new(p[0] as f32, p[1] as f32) * self.scale + self.offset
    }
    pub fn to_layout(&self, p: Pos2) -> [f64; 2] {
        let q = (p - self.offset) / self.scale;
        [q.x as f64, q.y as f64]
    }
}

/// The widget state and its link to the document.
pub struct GraphView {
    pub state: EditorState,
    pub user: UserState,
    pub kinds: AllKinds,
    pub xf: Transform,
    /// Widget node of each core id.
    pub ids: HashMap<String, eng::NodeId>,
    /// The document revision the widget shows.
    pub shown: Option<u64>,
    /// Responses to feed into the next frame (tests drive the widget this way).
    pub inject: Vec<NodeResponse>,
    /// Fit the whole graph into the view at the next frame (after opening a file).
    pub fit_pending: bool,
    /// Where the last frame drew the canvas (points); none in the viewer-only layout.
    pub canvas_rect: Option<egui::Rect>,
}

/// What the widget did this frame, as document edits to apply.
#[derive(Debug, PartialEq)]
pub enum ViewEdit {
    Added { kind: &'static str, pos: [f64; 2], node: eng::NodeId },
    Removed(String),
    Connected { from: PortRef, to: PortRef },
    Disconnected { to: PortRef },
    Moved(Vec<(String, [f64; 2])>),
    Selected,
}

impl GraphView {
    pub fn new(registry: Registry) -> Self {
        let kinds = AllKinds::new(&registry);
        GraphView {
            state: EditorState::new(1.0),
            user: UserState { registry, states: HashMap::new() },
            kinds,
            xf: Transform { scale: 1.0, offset: Vec2::new(40.0, 60.0) },
            ids: HashMap::new(),
            shown: None,
            inject: Vec::new(),
            fit_pending: true,
            canvas_rect: None,
        }
    }

    /// Rebuilds the widget from the graph, keeping selection and view.
    pub fn rebuild(&mut self, graph: &Graph, revision: u64) {
        let selected: Vec<String> = self.selected_ids();
        let mut g = eng::Graph::new();
        let mut ids = HashMap::new();
        let mut positions = std::mem::take(&mut self.state.node_positions);
        positions.clear();
        let mut order = Vec::new();
        for n in &graph.nodes {
            let Some(kind) = self.user.registry.node(&n.kind) else { continue };
            let id = g.add_node(n.id.clone(), NodeData { id: n.id.clone(), kind: kind.kind() }, |gr, nid| {
                add_ports(gr, &self.user.registry, nid, kind.kind())
            });
            positions.insert(id, self.xf.to_widget(edit::position(graph, &n.id)));
            ids.insert(n.id.clone(), id);
            order.push(id);
        }
        for e in &graph.edges {
            let (Some(&a), Some(&b)) = (ids.get(&e.from.node), ids.get(&e.to.node)) else { continue };
            let (Ok(out), Ok(inp)) = (g[a].get_output(&e.from.port), g[b].get_input(&e.to.port)) else { continue };
            g.add_connection(out, inp, 0);
        }
        self.state.graph = g;
        self.state.node_positions = positions;
        self.state.node_order = order;
        self.state.connection_in_progress = None;
        self.state.ongoing_box_selection = None;
        self.state.selected_nodes = selected.iter().filter_map(|s| ids.get(s).copied()).collect();
        self.ids = ids;
        self.shown = Some(revision);
    }

    pub fn selected_ids(&self) -> Vec<String> {
        self.state.selected_nodes.iter().filter_map(|n| self.state.graph.nodes.get(*n)).map(|n| n.user_data.id.clone()).collect()
    }

    /// Selects exactly the node with this core id.
    pub fn select(&mut self, id: &str) {
        self.state.selected_nodes = self.ids.get(id).copied().into_iter().collect();
    }

    fn port_ref_out(&self, out: eng::OutputId) -> Option<PortRef> {
        let o = self.state.graph.outputs.get(out)?;
        let n = &self.state.graph.nodes[o.node];
        let name = n.outputs.iter().find(|(_, id)| *id == out)?.0.clone();
        Some(PortRef { node: n.user_data.id.clone(), port: name })
    }

    fn port_ref_in(&self, inp: eng::InputId) -> Option<PortRef> {
        let i = self.state.graph.inputs.get(inp)?;
        let n = &self.state.graph.nodes[i.node];
        let name = n.inputs.iter().find(|(_, id)| *id == inp)?.0.clone();
        Some(PortRef { node: n.user_data.id.clone(), port: name })
    }

    /// Draws the widget and returns the edits it made. Zooming is done here so that the
    /// layout transform follows the widget's own scaling of node positions.
    pub fn show(&mut self, ui: &mut egui::Ui) -> Vec<ViewEdit> {
        ui.set_clip_rect(ui.max_rect());
        self.canvas_rect = Some(ui.max_rect());
        let scroll = if ui.rect_contains_pointer(ui.max_rect()) { ui.input(|i| i.smooth_scroll_delta.y) } else { 0.0 };
        ui.ctx().input_mut(|i| i.smooth_scroll_delta = Vec2::ZERO);
        if !self.state.pan_zoom.started {
            self.state.zoom(ui, 1.0);
            self.state.pan_zoom.started = true;
        }
        if scroll != 0.0 {
            let before = self.state.pan_zoom.zoom;
            self.state.zoom(ui, (scroll * 0.002).exp());
            let d = self.state.pan_zoom.zoom / before;
            if d != 1.0 {
                let c = self.state.pan_zoom.clip_rect.size() / 2.0 - self.state.pan_zoom.pan;
                self.xf = Transform { scale: self.xf.scale * d, offset: (self.xf.offset - c) * d + c };
            }
        }
        if self.fit_pending {
            self.fit(ui);
        }
        let inject = std::mem::take(&mut self.inject);
        let resp = self.state.draw_graph_editor(ui, &self.kinds, &mut self.user, inject);
        self.edits(resp.node_responses)
    }

    /// Turns the widget's responses into document edits (the widget already shows them).
    pub fn edits(&mut self, responses: Vec<NodeResponse>) -> Vec<ViewEdit> {
        let mut out = Vec::new();
        let mut moved: Vec<eng::NodeId> = Vec::new();
        for r in responses {
            match r {
                eng::NodeResponse::CreatedNode(node) => {
                    let kind = self.state.graph[node].user_data.kind;
                    let pos = self.xf.to_layout(self.state.node_positions[node]);
                    out.push(ViewEdit::Added { kind, pos, node });
                }
                eng::NodeResponse::DeleteNodeFull { node, .. } => {
                    self.ids.remove(&node.user_data.id);
                    out.push(ViewEdit::Removed(node.user_data.id));
                }
                eng::NodeResponse::ConnectEventEnded { output, input, .. } => {
                    if let (Some(from), Some(to)) = (self.port_ref_out(output), self.port_ref_in(input)) {
                        out.push(ViewEdit::Connected { from, to });
                    }
                }
                eng::NodeResponse::DisconnectEvent { input, .. } => {
                    // Removing a node reports its connections too; only live inputs count.
                    if let Some(to) = self.port_ref_in(input) {
                        out.push(ViewEdit::Disconnected { to });
                    }
                }
                eng::NodeResponse::MoveNode { node, .. } => {
                    moved.push(node);
                    if self.state.selected_nodes.contains(&node) {
                        moved.extend(self.state.selected_nodes.iter().copied());
                    }
                }
                eng::NodeResponse::SelectNode(_) => out.push(ViewEdit::Selected),
                _ => {}
            }
        }
        moved.sort();
        moved.dedup();
        let positions: Vec<(String, [f64; 2])> = moved
            .into_iter()
            .filter_map(|n| {
                Some((self.state.graph.nodes.get(n)?.user_data.id.clone(), self.xf.to_layout(*self.state.node_positions.get(n)?)))
            })
            .collect();
        if !positions.is_empty() {
            out.push(ViewEdit::Moved(positions));
        }
        out
    }

    /// Zooms and pans so that every node is in view (zoom at most 1).
    pub fn fit(&mut self, ui: &egui::Ui) {
        self.fit_pending = false;
        let layout: Vec<(eng::NodeId, [f64; 2])> = self.state.node_positions.iter().map(|(n, p)| (n, self.xf.to_layout(*p))).collect();
        let pts: Vec<Pos2> = layout.iter().map(|(_, p)| Pos2::new(p[0] as f32, p[1] as f32)).collect();
        if pts.is_empty() {
            return;
        }
        let bbox = egui::Rect::from_points(&pts);
        // Node widgets reach about 200 × 150 points right of and below their position.
        let need = bbox.size() + Vec2::new(260.0, 190.0);
        let avail = ui.max_rect().size();
        let scale = (avail.x / need.x).min(avail.y / need.y).clamp(0.2, 1.0);
        let style = ui.style().clone();
        self.state.pan_zoom.zoom(ui.clip_rect(), &style, scale / self.state.pan_zoom.zoom);
        self.state.pan_zoom.pan = Vec2::ZERO;
        let zoom = self.state.pan_zoom.zoom;
        self.xf = Transform { scale: zoom, offset: Vec2::new(30.0, 30.0) - bbox.min.to_vec2() * zoom };
        for (n, p) in layout {
            self.state.node_positions[n] = self.xf.to_widget(p);
        }
    }

    /// Removes a connection the widget made but the document refused.
    pub fn undo_connection(&mut self, from: &PortRef, to: &PortRef) {
        let (Some(&a), Some(&b)) = (self.ids.get(&from.node), self.ids.get(&to.node)) else { return };
        let (Ok(out), Ok(inp)) = (self.state.graph[a].get_output(&from.port), self.state.graph[b].get_input(&to.port)) else { return };
        self.state.graph.remove_connection(inp, out);
    }

    /// The widget node created for `kind` gets its core id.
    pub fn name_node(&mut self, node: eng::NodeId, id: &str) {
        self.state.graph[node].user_data.id = id.to_string();
        self.state.graph[node].label = id.to_string();
        self.ids.insert(id.to_string(), node);
    }

    /// Number of connections the widget shows (tests).
    pub fn connection_count(&self) -> usize {
        self.state.graph.iter_connections().count()
    }
}
