//! Manipulators in the viewer, bound to the graph's own nodes: a drag orbits an `OrbitCamera`
//! (with shift or the secondary button it pans; the wheel zooms), moves a `MoveObject`'s object
//! in the view's plane, turns a `TurnEnvironment`'s sky; a click picks the object under the
//! pointer and selects the node that edits its material; a stroke paints with a
//! `PaintMaterial` or `VolumePaint` node as the brush. Each drag or stroke is one undo step and
//! ends as parameters in the graph file: a stroke adds a copy of the brush node per dab,
//! chained after it, with the dab's place set.

use crate::app::EditorApp;
use crate::edit;
use crate::pick::{Picked, Probe};
use crate::tool::*;
use crate::viewer::ViewerInput;
use glam::Vec2;
use relume_core::ParamValue;

impl EditorApp {
    /// The tools the open graph offers: one per node kind it has, and picking where the viewed
    /// image comes from a scene.
    pub fn tools(&self) -> Vec<Tool> {
        let has = |kind: &str| self.doc.graph.nodes.iter().any(|n| n.kind == kind);
        let scene = || self.view_node().is_some_and(|n| crate::pick::upstream_port(&self.doc.graph, &self.registry, &n, "Scene").is_some());
        Tool::ALL.into_iter().filter(|t| t.kind().map_or_else(scene, has)).collect()
    }

    /// The node that renders the viewed image.
    pub fn view_node(&self) -> Option<String> {
        self.view_port().map(|p| p.node)
    }

    /// The node a tool edits: the selected node where it is of the tool's kind, else one the
    /// viewed image depends on (for a brush the last of its chain), else the first of the kind.
    pub fn bound_node(&self, tool: Tool) -> Option<String> {
        let kind = tool.kind()?;
        let g = &self.doc.graph;
        let of_kind = |id: &String| g.node(id).is_some_and(|n| n.kind == kind);
        if let [id] = self.view.selected_ids().as_slice() {
            if of_kind(id) {
                return Some(id.clone());
            }
        }
        let upstream = self.view_node().map(|n| g.upstream(&n)).unwrap_or_default();
        let feeds_same_kind = |id: &str| g.edges.iter().any(|e| e.from.node == id && of_kind(&e.to.node));
        let mut candidates: Vec<&String> = g.nodes.iter().map(|n| &n.id).filter(|id| of_kind(id)).collect();
        candidates.sort_by_key(|id| (!upstream.contains(*id), feeds_same_kind(id)));
        candidates.first().map(|id| (*id).clone())
    }

    /// Carries out what the pointer did on the image with the current tool.
    pub fn manipulate(&mut self, input: &ViewerInput) {
        let Some(tool) = self.tool else { return };
        if input.clicked && tool == Tool::Pick {
            if let Some(p) = input.pointer {
                self.pick_and_select(p, input.size);
            }
            return;
        }
        if input.pressed || (input.clicked && tool.chain_ports().is_some()) {
            self.begin_gesture(tool);
        }
        if input.dragging || input.pressed || input.clicked {
            self.drag(input);
        }
        if input.scroll != 0.0 && tool == Tool::Orbit && self.gesture.is_none() {
            self.zoom(input.scroll);
        }
        if input.released || input.clicked {
            self.gesture = None;
            self.doc.seal();
        }
    }

    fn begin_gesture(&mut self, tool: Tool) {
        self.doc.seal();
        let Some(node) = self.bound_node(tool) else {
            self.status = format!("no {} node in the graph for the {} tool", tool.kind().unwrap_or("?"), tool.label());
            return;
        };
        let start = self.doc.graph.node(&node).map(|n| n.params.clone()).unwrap_or_default();
        let probe = match tool {
            Tool::Move | Tool::Paint | Tool::PaintVolume => {
                match self.view_node().map(|v| Probe::new(self.runner.engine(), &self.doc.graph, &v)) {
                    Some(Ok(p)) => Some(p),
                    Some(Err(e)) => {
                        self.status = format!("the {} tool needs the scene behind the image: {e}", tool.label());
                        return;
                    }
                    None => return,
                }
            }
            _ => None,
        };
        let tag = format!("gesture:{node}");
        self.gesture = Some(Gesture { tool, tag, node, start, total: egui::Vec2::ZERO, probe, last_dab: None, dabs: 0 });
    }

    /// A parameter of the gesture's node as it was when the drag began (its default if unset).
    fn start_value(&self, g: &Gesture, name: &str) -> Option<ParamValue> {
        if let Some((_, v)) = g.start.iter().find(|(n, _)| n == name) {
            return Some(v.clone());
        }
        let kind = self.doc.graph.node(&g.node)?.kind.clone();
        self.registry.node(&kind)?.schema().get(name)?.default.clone()
    }

    fn drag(&mut self, input: &ViewerInput) {
        let Some(mut g) = self.gesture.take() else { return };
        if let (Some(p), Some(o)) = (input.pointer, input.origin) {
            g.total = p - o;
        }
        let (w, h) = (input.size[0].max(1) as f32, input.size[1].max(1) as f32);
        let f = |app: &Self, name: &str| float(app.start_value(&g, name).as_ref());
        let edits: Vec<(&str, ParamValue)> = match g.tool {
            Tool::Orbit if input.alternate => vec![
                ("pan_right", ParamValue::Float((f(self, "pan_right") - g.total.x / w) as f64)),
                ("pan_up", ParamValue::Float((f(self, "pan_up") + g.total.y / h) as f64)),
            ],
            Tool::Orbit => vec![
                ("azimuth", ParamValue::Float(wrap_deg(f(self, "azimuth") - ORBIT_DEG_PER_WIDTH * g.total.x / w) as f64)),
                ("elevation", ParamValue::Float((f(self, "elevation") - ORBIT_DEG_PER_HEIGHT * g.total.y / h).clamp(-89.0, 89.0) as f64)),
            ],
            Tool::Turn if input.alternate => {
                vec![("tilt_deg", ParamValue::Float(wrap_deg(f(self, "tilt_deg") + TILT_DEG_PER_HEIGHT * g.total.y / h) as f64))]
            }
            Tool::Turn => {
                vec![("rotation_deg", ParamValue::Float(wrap_deg(f(self, "rotation_deg") + TURN_DEG_PER_WIDTH * g.total.x / w) as f64))]
            }
            Tool::Move => {
                let probe = g.probe.as_ref().expect("made when the move began");
                let (right, up) = probe.axes();
                let k = probe.units_per_pixel(input.size[0]);
                let t0 = vec3(self.start_value(&g, "translation").as_ref());
                vec![("translation", tuple(t0 + (right * g.total.x - up * g.total.y) * k))]
            }
            Tool::Paint | Tool::PaintVolume => {
                if let Some(p) = input.pointer {
                    self.dab(&mut g, p, input.size);
                }
                vec![]
            }
            Tool::Pick => vec![],
        };
        if !edits.is_empty() {
            if let Err(e) = self.set_params_held(&g.tag, &g.node, edits) {
                self.status = e;
            }
        }
        self.gesture = Some(g);
    }

    /// Sets parameters of one node, checked against its schema, as one undo step that the
    /// rest of the gesture merges into.
    fn set_params_held(&mut self, tag: &str, id: &str, edits: Vec<(&str, ParamValue)>) -> Result<(), String> {
        let kind = self.doc.graph.node(id).map(|n| n.kind.clone()).ok_or_else(|| format!("no node \"{id}\""))?;
        let schema = self.registry.node(&kind).ok_or_else(|| format!("unknown kind {kind}"))?.schema();
        let mut checked = Vec::new();
        for (name, v) in edits {
            let spec = schema.get(name).ok_or_else(|| format!("{kind} has no parameter {name}"))?;
            let v = spec.check(&v).map_err(|m| format!("{id}.{name}: {m}"))?;
            // What the node has now, written or by default: an unchanged value is no edit.
            let now = self.doc.graph.node(id).and_then(|d| d.param(name)).or(spec.default.as_ref());
            if now != Some(&v) {
                checked.push((name, v));
            }
        }
        if checked.is_empty() {
            return Ok(());
        }
        self.apply(tag, true, |g| checked.into_iter().for_each(|(n, v)| g.set_param(id, n, v)));
        self.doc.hold();
        Ok(())
    }

    fn zoom(&mut self, scroll: f32) {
        let Some(node) = self.bound_node(Tool::Orbit) else { return };
        let d = self.doc.graph.node(&node).and_then(|n| n.param("distance")).map(|v| float(Some(v))).unwrap_or(1.0);
        let d = (d * (-ZOOM_PER_POINT * scroll).exp()).clamp(0.01, 100.0);
        if let Err(e) = self.set_param(&node, "distance", ParamValue::Float(d as f64)) {
            self.status = e;
        }
    }

    /// A dab of the stroke at pixel `p`: a new brush node after the last one, or, within half
    /// the brush's radius of the last dab (or past the most dabs a stroke adds), that dab moved.
    fn dab(&mut self, g: &mut Gesture, p: egui::Pos2, size: [usize; 2]) {
        let Some(hit) = g.probe.as_mut().and_then(|probe| probe.pick(p, size)) else { return };
        let (place, params) = match self.dab_params(g, &hit) {
            Ok(x) => x,
            Err(e) => {
                self.status = e;
                return;
            }
        };
        let radius = float(self.doc.graph.node(&g.node).and_then(|n| n.param("radius")).or(self.start_value(g, "radius").as_ref()));
        let near = g.last_dab.is_some_and(|last| last.distance(place) < 0.5 * radius);
        if near {
            return;
        }
        let (input, out) = g.tool.chain_ports().expect("a brush");
        if g.dabs >= MAX_DABS {
            if let Err(e) = self.set_params_held(&g.tag, &g.node, params) {
                self.status = e;
            }
        } else {
            let after = g.node.clone();
            let made = self.apply(&g.tag, false, |graph| edit::insert_copy_after(graph, &after, out, input, params));
            self.doc.hold();
            let Some(id) = made else { return };
            g.node = id;
            g.dabs += 1;
        }
        g.last_dab = Some(place);
        self.status = format!("{} dab{} on {}", g.dabs, if g.dabs == 1 { "" } else { "s" }, hit.object);
    }

    /// Where a dab on `hit` goes, and the brush node's parameters that put it there.
    fn dab_params(&self, g: &Gesture, hit: &Picked) -> Result<Dab, String> {
        match g.tool {
            Tool::Paint => {
                let uv: Vec2 = hit.uv.ok_or_else(|| format!("{} has no texture coordinates to paint", hit.object))?;
                let dynamic = g.probe.as_ref().is_some_and(|p| p.scene().objects.iter().any(|o| o.name == hit.object && o.dynamic));
                if !dynamic {
                    return Err(format!("{} is not a dynamic object: only dynamic objects' materials are painted", hit.object));
                }
                let params = vec![
                    ("object", ParamValue::Text(hit.object.clone())),
                    ("u", ParamValue::Float(uv.x as f64)),
                    ("v", ParamValue::Float(uv.y as f64)),
                ];
                Ok((uv.extend(0.0), params))
            }
            _ => Ok((hit.inside, vec![("centre", tuple(hit.inside))])),
        }
    }

    /// Picks the object under pixel `p`, then selects the node that edits its material: one
    /// whose `object` is that object, else a material node bound to no object yet, which is
    /// bound to it (one undo step).
    pub fn pick_and_select(&mut self, p: egui::Pos2, size: [usize; 2]) -> Option<Picked> {
        let view = self.view_node()?;
        let hit = match Probe::new(self.runner.engine(), &self.doc.graph, &view).map(|mut probe| probe.pick(p, size)) {
            Ok(Some(hit)) => hit,
            Ok(None) => {
                self.status = "nothing under the pointer".into();
                return None;
            }
            Err(e) => {
                self.status = format!("cannot pick: {e}");
                return None;
            }
        };
        let g = &self.doc.graph;
        let object_is = |n: &relume_core::graph::NodeDecl, name: &str| n.param("object") == Some(&ParamValue::Text(name.into()));
        let material_kinds = ["MaterialProject", "PaintMaterial"];
        let bound = g.nodes.iter().filter(|n| material_kinds.contains(&n.kind.as_str())).find(|n| object_is(n, &hit.object));
        let free = g.nodes.iter().find(|n| n.kind == "MaterialProject" && (object_is(n, "") || n.param("object").is_none()));
        let chosen = match (bound, free) {
            (Some(n), _) => Some(n.id.clone()),
            (None, Some(n)) => {
                let id = n.id.clone();
                let _ = self.set_param(&id, "object", ParamValue::Text(hit.object.clone()));
                self.doc.seal();
                Some(id)
            }
            (None, None) => None,
        };
        self.status = match &chosen {
            Some(id) => format!("picked {} — its material: {id}", hit.object),
            None => format!("picked {} — no material node edits it", hit.object),
        };
        if let Some(id) = &chosen {
            self.view.rebuild(&self.doc.graph, self.doc.revision);
            self.view.select(id);
        }
        Some(hit)
    }
}
