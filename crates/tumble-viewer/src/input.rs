//! The talk's demo keys and the mouse, as a state machine with no window attached, so the key
//! map is unit-tested. The window (window.rs) translates winit events into [`Key`]s and mouse
//! calls, and carries out the returned [`Action`]s.

use tumble::stages::batching::Batcher;

use crate::camera::Camera;
use crate::draw::DrawSettings;

/// Keys the viewer reacts to, independent of the window library.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// A printable key, lower case.
    Char(char),
    Space,
    Escape,
    Left,
    Right,
    Up,
    Down,
}

/// Where a stage of the step runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Executor {
    Cpu,
    Gpu,
}

impl Executor {
    fn toggled(self) -> Self {
        match self {
            Executor::Cpu => Executor::Gpu,
            Executor::Gpu => Executor::Cpu,
        }
    }
}

/// What `b` shows: nothing special, every batch in its colour, or a single batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchView {
    Off,
    All,
    One(usize),
}

/// What a key asks of the viewer beyond the state change.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    None,
    /// Rebuild the world from the scene.
    Reset,
    /// Advance one step (the simulation is paused).
    Step,
    /// Take the profile overlay's numbers now (and again every second while `profile` is on).
    Profile,
    /// Run the solver stage (and its batching) on this executor from the next step.
    Solver(Executor),
    /// Batch constraints with this batcher from the next step.
    Batcher(Batcher),
    Quit,
}

/// The key list: the help overlay (`h`), also printed when the window opens.
pub const HELP: &str = "\
tumble view keys:
  space        reset the scene
  i            start / stop the simulation
  s            single step (stops the simulation)
  p            profile: stage timings, pair and contact counts, batch histogram
  c            draw contact points and normals
  b            constraint batches: all in colours / one batch at a time / off
  u            solver (and its batching) on CPU / GPU
  d            batcher: greedy colors / the talk's rounds
  w            wireframe / solid
  h            this help (on / off)
  q, escape    quit
  cursor keys  orbit the camera;  z / x  move closer / farther;  mouse drag  orbit";

/// Camera turn per cursor key press (radians) and per pixel of mouse drag.
const KEY_TURN: f32 = 0.08;
const DRAG_TURN: f32 = 0.005;
/// Distance factor per z / x press.
const ZOOM_STEP: f32 = 0.9;

/// The viewer's state as the keys and mouse change it.
#[derive(Clone, Debug, PartialEq)]
pub struct InputState {
    pub camera: Camera,
    pub running: bool,
    pub profile: bool,
    /// The help overlay is shown.
    pub help: bool,
    pub contacts: bool,
    pub wireframe: bool,
    pub batches: BatchView,
    pub solver: Executor,
    pub batcher: Batcher,
    /// Batches of the last step, for cycling through single batches with `b`.
    pub batch_count: usize,
    /// Where the mouse button went down or the cursor last was while dragging (pixels).
    drag_from: Option<(f32, f32)>,
}

impl InputState {
    /// The simulation starts running, drawn solid, every stage on the CPU.
    pub fn new(camera: Camera) -> Self {
        Self {
            camera,
            running: true,
            profile: false,
            help: false,
            contacts: false,
            wireframe: false,
            batches: BatchView::Off,
            solver: Executor::Cpu,
            batcher: Batcher::default(),
            batch_count: 0,
            drag_from: None,
        }
    }

    pub fn draw_settings(&self) -> DrawSettings {
        DrawSettings {
            contacts: self.contacts,
            wireframe: self.wireframe,
            batches: self.batches,
        }
    }

    pub fn key(&mut self, key: Key) -> Action {
        match key {
            Key::Space => Action::Reset,
            Key::Escape | Key::Char('q') => Action::Quit,
            Key::Left => self.turn(-KEY_TURN, 0.0),
            Key::Right => self.turn(KEY_TURN, 0.0),
            Key::Up => self.turn(0.0, KEY_TURN),
            Key::Down => self.turn(0.0, -KEY_TURN),
            Key::Char('z') => {
                self.camera.zoom(ZOOM_STEP);
                Action::None
            }
            Key::Char('x') => {
                self.camera.zoom(1.0 / ZOOM_STEP);
                Action::None
            }
            Key::Char('i') => {
                self.running = !self.running;
                Action::None
            }
            Key::Char('s') => {
                self.running = false;
                Action::Step
            }
            Key::Char('p') => {
                self.profile = !self.profile;
                if self.profile {
                    Action::Profile
                } else {
                    Action::None
                }
            }
            Key::Char('c') => {
                self.contacts = !self.contacts;
                Action::None
            }
            Key::Char('w') => {
                self.wireframe = !self.wireframe;
                Action::None
            }
            Key::Char('b') => {
                self.batches = match self.batches {
                    BatchView::Off => BatchView::All,
                    BatchView::All if self.batch_count > 0 => BatchView::One(0),
                    BatchView::One(batch) if batch + 1 < self.batch_count => {
                        BatchView::One(batch + 1)
                    }
                    BatchView::All | BatchView::One(_) => BatchView::Off,
                };
                Action::None
            }
            Key::Char('u') => {
                self.solver = self.solver.toggled();
                Action::Solver(self.solver)
            }
            Key::Char('d') => {
                self.batcher = self.batcher.next();
                Action::Batcher(self.batcher)
            }
            Key::Char('h') => {
                self.help = !self.help;
                Action::None
            }
            Key::Char(_) => Action::None,
        }
    }

    /// The left mouse button went down (`pressed`) or up at `position` (pixels).
    pub fn mouse_button(&mut self, pressed: bool, position: (f32, f32)) {
        self.drag_from = pressed.then_some(position);
    }

    /// The cursor moved to `position` (pixels): while dragging, orbit the camera with it.
    pub fn cursor_moved(&mut self, position: (f32, f32)) {
        if let Some((x, y)) = self.drag_from {
            // Dragging right turns the scene right (the eye left); dragging up tilts it down.
            self.camera
                .orbit(-(position.0 - x) * DRAG_TURN, (position.1 - y) * DRAG_TURN);
            self.drag_from = Some(position);
        }
    }

    fn turn(&mut self, yaw: f32, pitch: f32) -> Action {
        self.camera.orbit(yaw, pitch);
        Action::None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn state() -> InputState {
        InputState::new(Camera::look_at(Vec3::new(0.0, 2.0, 10.0), Vec3::ZERO))
    }

    /// Presses `key` on a fresh state; returns the action and the state after.
    fn press(key: Key) -> (Action, InputState) {
        let mut state = state();
        let action = state.key(key);
        (action, state)
    }

    #[test]
    fn space_resets_q_and_escape_quit() {
        assert_eq!(press(Key::Space), (Action::Reset, state()));
        assert_eq!(press(Key::Char('q')), (Action::Quit, state()));
        assert_eq!(press(Key::Escape), (Action::Quit, state()));
    }

    #[test]
    fn h_toggles_the_help_overlay() {
        let mut s = state();
        assert!(!s.help);
        assert_eq!(s.key(Key::Char('h')), Action::None);
        assert!(s.help);
        assert_eq!(s.key(Key::Char('h')), Action::None);
        assert!(!s.help);
    }

    #[test]
    fn i_toggles_the_simulation_and_s_steps_it_paused() {
        let mut s = state();
        assert!(s.running);
        assert_eq!(s.key(Key::Char('i')), Action::None);
        assert!(!s.running);
        assert_eq!(s.key(Key::Char('i')), Action::None);
        assert!(s.running);
        assert_eq!(s.key(Key::Char('s')), Action::Step);
        assert!(!s.running);
        assert_eq!(s.key(Key::Char('s')), Action::Step);
        assert!(!s.running);
    }

    #[test]
    fn p_c_w_toggle_profile_contacts_wireframe() {
        let mut s = state();
        assert_eq!(s.key(Key::Char('p')), Action::Profile);
        assert!(s.profile);
        assert_eq!(s.key(Key::Char('p')), Action::None);
        assert!(!s.profile);

        assert_eq!(s.key(Key::Char('c')), Action::None);
        assert!(s.contacts && s.draw_settings().contacts);
        s.key(Key::Char('c'));
        assert!(!s.contacts);

        assert_eq!(s.key(Key::Char('w')), Action::None);
        assert!(s.wireframe && s.draw_settings().wireframe);
        s.key(Key::Char('w'));
        assert!(!s.wireframe);
    }

    #[test]
    fn b_cycles_all_batches_then_each_batch_then_off() {
        let mut s = state();
        s.batch_count = 2;
        let mut seen = Vec::new();
        for _ in 0..5 {
            s.key(Key::Char('b'));
            seen.push(s.batches);
        }
        use BatchView::*;
        assert_eq!(seen, [All, One(0), One(1), Off, All]);
        // With no batches (nothing touching) there is no single batch to show.
        s.batch_count = 0;
        assert!(matches!(s.key(Key::Char('b')), Action::None));
        assert_eq!(s.batches, Off);
    }

    #[test]
    fn u_switches_the_solver_and_d_the_batcher() {
        let mut s = state();
        assert_eq!(s.key(Key::Char('u')), Action::Solver(Executor::Gpu));
        assert_eq!(s.solver, Executor::Gpu);
        assert_eq!(s.key(Key::Char('u')), Action::Solver(Executor::Cpu));
        assert_eq!(s.solver, Executor::Cpu);
        assert_eq!(s.key(Key::Char('d')), Action::Batcher(Batcher::Rounds));
        assert_eq!((s.batcher, s.solver), (Batcher::Rounds, Executor::Cpu));
        assert_eq!(s.key(Key::Char('d')), Action::Batcher(Batcher::Colors));
        assert_eq!(s.batcher, Batcher::Colors);
    }

    #[test]
    fn cursor_keys_orbit_and_z_x_zoom() {
        let start = state().camera;
        let (_, left) = press(Key::Left);
        let (_, right) = press(Key::Right);
        assert!(left.camera.yaw < start.yaw && right.camera.yaw > start.yaw);
        let (_, up) = press(Key::Up);
        let (_, down) = press(Key::Down);
        assert!(up.camera.pitch > start.pitch && down.camera.pitch < start.pitch);
        let (_, closer) = press(Key::Char('z'));
        let (_, farther) = press(Key::Char('x'));
        assert!(closer.camera.distance < start.distance);
        assert!(farther.camera.distance > start.distance);
        // Orbiting keeps the target.
        assert_eq!(left.camera.target, start.target);
    }

    #[test]
    fn mouse_drag_orbits_only_while_pressed() {
        let mut s = state();
        let start = s.camera;
        s.cursor_moved((10.0, 10.0));
        assert_eq!(s.camera, start, "moving without a button does nothing");
        s.mouse_button(true, (10.0, 10.0));
        s.cursor_moved((50.0, 10.0));
        assert!(s.camera.yaw != start.yaw);
        let dragged = s.camera;
        s.mouse_button(false, (50.0, 10.0));
        s.cursor_moved((90.0, 30.0));
        assert_eq!(s.camera, dragged);
    }

    #[test]
    fn other_keys_change_nothing() {
        assert_eq!(press(Key::Char('7')), (Action::None, state()));
    }
}
