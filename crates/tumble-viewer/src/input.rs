//! The talk's demo keys and the mouse, as a state machine with no window attached, so the key
//! map is unit-tested. The window (window.rs) translates winit events into [`Key`]s and mouse
//! calls, and carries out the returned [`Action`]s.
//!
//! The mouse: a left drag that starts on a dynamic body pulls that body (the world's drag,
//! see [`pick`](crate::pick)); one that starts anywhere else, and every right drag, orbits the
//! camera, so the camera can still be turned when bodies fill the picture.

use tumble::World;
use tumble::stages::batching::Batcher;

use crate::camera::Camera;
use crate::draw::DrawSettings;
use crate::pick::{self, Grab};

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

/// Mouse buttons the viewer reacts to, independent of the window library.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MouseButton {
    /// Picks and drags a body, or orbits the camera off the bodies.
    Left,
    /// Orbits the camera.
    Right,
}

/// What the held mouse button does as the cursor moves.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Gesture {
    /// Turning the camera; the cursor was last at `last` (pixels).
    Orbit {
        button: MouseButton,
        last: (f32, f32),
    },
    /// Pulling a body (left button).
    Drag(Grab),
}

impl Gesture {
    fn button(&self) -> MouseButton {
        match self {
            Gesture::Orbit { button, .. } => *button,
            Gesture::Drag(_) => MouseButton::Left,
        }
    }
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
  c            contacts and constraints: points, normals, joints, the drag
  b            constraint batches: all in colours / one batch at a time / off
  u            solver (and its batching) on CPU / GPU
  d            batcher: greedy colors / the talk's rounds
  w            wireframe / solid
  h            this help (on / off)
  q, escape    quit
  cursor keys  orbit the camera;  z / x  move closer / farther;  mouse wheel  zoom
  left drag    on a body: pull it by that point (let go to drop it);  elsewhere: orbit
  right drag   orbit the camera";

/// The help overlay of the particle demo's window: the keys that mean something there (it has
/// no contacts, batches or bodies to pick).
pub const PARTICLE_HELP: &str = "\
tumble view keys (particle demo):
  space        reset the particles
  i            start / stop the simulation
  s            single step (stops the simulation)
  p            profile: stage timings
  u            the whole step on CPU / GPU (the particles carry over)
  w            wireframe / solid
  h            this help (on / off)
  q, escape    quit
  cursor keys  orbit the camera;  z / x  move closer / farther;  mouse wheel  zoom
  left or right drag   orbit the camera";

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
    /// The window's size in pixels, which the cursor's pixels are relative to.
    pub viewport: (u32, u32),
    /// What the held mouse button does; `None` while no button is held.
    gesture: Option<Gesture>,
}

impl InputState {
    /// The simulation starts running, drawn solid, every stage on the CPU, in a window of
    /// `viewport` pixels.
    pub fn new(camera: Camera, viewport: (u32, u32)) -> Self {
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
            viewport,
            gesture: None,
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
            Key::Space => {
                // The rebuilt world has no drag, and the grabbed handle is not its body.
                self.gesture = None;
                Action::Reset
            }
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

    /// The body the mouse is dragging, if any.
    pub fn grab(&self) -> Option<&Grab> {
        match &self.gesture {
            Some(Gesture::Drag(grab)) => Some(grab),
            _ => None,
        }
    }

    /// `button` went down (`pressed`) or up with the cursor at `position` (pixels). The left
    /// button picks the dynamic body under the cursor and starts dragging it in `world`, or
    /// else orbits (always, with no `world`: the particle demo has no bodies to pick); letting
    /// go of it ends the drag. While one button is held, the other does nothing.
    pub fn mouse_button(
        &mut self,
        button: MouseButton,
        pressed: bool,
        position: (f32, f32),
        world: Option<&mut World>,
    ) {
        if !pressed {
            match self.gesture {
                // Only letting go of the button that started the gesture ends it.
                Some(gesture) if gesture.button() == button => {
                    self.gesture = None;
                    if let (Gesture::Drag(_), Some(world)) = (gesture, world) {
                        world.clear_drag();
                    }
                }
                _ => {}
            }
            return;
        }
        if self.gesture.is_some() {
            return;
        }
        let grab = match (button, world) {
            (MouseButton::Left, Some(world)) => {
                pick::pick(world, &self.camera, position, self.viewport)
                    // The picked body exists and the hit point is finite, so the world takes it.
                    .filter(|grab| grab.apply(world).is_ok())
            }
            _ => None,
        };
        self.gesture = Some(match grab {
            Some(grab) => Gesture::Drag(grab),
            None => Gesture::Orbit {
                button,
                last: position,
            },
        });
    }

    /// The cursor moved to `position` (pixels): orbit the camera with it, or move the dragged
    /// body's target under it (in `world`), while a button is held.
    pub fn cursor_moved(&mut self, position: (f32, f32), world: Option<&mut World>) {
        match &mut self.gesture {
            None => {}
            Some(Gesture::Orbit { last, .. }) => {
                let (x, y) = *last;
                // Dragging right turns the scene right (the eye left); dragging up tilts it down.
                self.camera
                    .orbit(-(position.0 - x) * DRAG_TURN, (position.1 - y) * DRAG_TURN);
                *last = position;
            }
            Some(Gesture::Drag(grab)) => {
                // With the picked point behind the camera (orbited past it with the keys) there
                // is no point under the cursor: the target stays.
                let Some(target) =
                    pick::drag_target(&self.camera, position, self.viewport, grab.picked_at)
                else {
                    return;
                };
                grab.target = target;
                // The body is gone from `world`, or there is no world: nothing is left to drag.
                let gone = match world {
                    Some(world) => {
                        let gone = grab.apply(world).is_err();
                        if gone {
                            world.clear_drag();
                        }
                        gone
                    }
                    None => true,
                };
                if gone {
                    self.gesture = None;
                }
            }
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

    const VIEWPORT: (u32, u32) = (800, 600);

    fn state() -> InputState {
        InputState::new(
            Camera::look_at(Vec3::new(0.0, 2.0, 10.0), Vec3::ZERO),
            VIEWPORT,
        )
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

    /// A ground plane at y = -0.5 and a unit box on it, centred where [`state`]'s camera looks.
    fn scene() -> (World, tumble::BodyHandle) {
        let mut world = World::new(tumble::StepConfig::default()).unwrap();
        world
            .add_body(tumble::BodyDesc::fixed(tumble::Shape::plane(Vec3::Y, -0.5)))
            .unwrap();
        let cube = world
            .add_body(tumble::BodyDesc::dynamic(tumble::Shape::cuboid(
                Vec3::splat(0.5),
            )))
            .unwrap();
        (world, cube)
    }

    /// The picture's centre (on the box), its top-left corner (sky) and bottom middle (ground).
    const ON_THE_BOX: (f32, f32) = (400.0, 300.0);
    const ON_THE_SKY: (f32, f32) = (10.0, 10.0);
    const ON_THE_GROUND: (f32, f32) = (400.0, 590.0);

    #[test]
    fn mouse_drag_orbits_only_while_pressed() {
        let (mut world, _) = scene();
        let mut s = state();
        let start = s.camera;
        s.cursor_moved((10.0, 10.0), Some(&mut world));
        assert_eq!(s.camera, start, "moving without a button does nothing");
        s.mouse_button(MouseButton::Left, true, ON_THE_SKY, Some(&mut world));
        assert_eq!(s.camera, start, "pressing does not turn the camera");
        s.cursor_moved((50.0, 10.0), Some(&mut world));
        assert!(s.camera.yaw != start.yaw);
        let dragged = s.camera;
        s.mouse_button(MouseButton::Left, false, (50.0, 10.0), Some(&mut world));
        s.cursor_moved((90.0, 30.0), Some(&mut world));
        assert_eq!(s.camera, dragged);
        assert_eq!(s.grab(), None);
    }

    #[test]
    fn a_left_press_on_a_body_drags_it_until_let_go() {
        let (mut world, cube) = scene();
        let mut s = state();
        let start = s.camera;
        s.mouse_button(MouseButton::Left, true, ON_THE_BOX, Some(&mut world));
        let grab = *s.grab().expect("the press is on the box");
        assert_eq!(grab.body, cube);
        // Picked on its front face (+Z, towards the camera), pulled where it was picked.
        assert!((grab.picked_at.z - 0.5).abs() < 1e-4, "{grab:?}");
        assert_eq!(grab.target, grab.picked_at);

        // Moving the cursor up moves the target up, and the camera stays.
        s.cursor_moved((ON_THE_BOX.0, ON_THE_BOX.1 - 100.0), Some(&mut world));
        let moved = *s.grab().unwrap();
        assert_eq!((moved.body, moved.local_anchor), (cube, grab.local_anchor));
        assert!(moved.target.y > grab.target.y + 0.5, "{moved:?}");
        assert_eq!(s.camera, start);
        // The world pulls the box towards the new target.
        for _ in 0..30 {
            world.step();
        }
        assert!(world.pose(cube).unwrap().position.y > 0.1);

        // The right button does nothing while the left drags.
        s.mouse_button(MouseButton::Right, true, ON_THE_BOX, Some(&mut world));
        s.cursor_moved((ON_THE_BOX.0 + 50.0, ON_THE_BOX.1), Some(&mut world));
        s.mouse_button(MouseButton::Right, false, ON_THE_BOX, Some(&mut world));
        assert_eq!(s.camera, start);
        assert_eq!(s.grab().unwrap().body, cube);

        // Letting go ends the drag: the box falls back to the ground.
        s.mouse_button(MouseButton::Left, false, ON_THE_BOX, Some(&mut world));
        assert_eq!(s.grab(), None);
        for _ in 0..120 {
            world.step();
        }
        let y = world.pose(cube).unwrap().position.y;
        assert!(y.abs() < 0.05, "the box was let go but hangs at {y}");
    }

    #[test]
    fn a_press_off_the_bodies_drags_nothing() {
        for (button, at) in [
            (MouseButton::Left, ON_THE_SKY),
            (MouseButton::Left, ON_THE_GROUND),
            (MouseButton::Right, ON_THE_BOX),
        ] {
            let (mut world, cube) = scene();
            let mut s = state();
            let start = s.camera;
            s.mouse_button(button, true, at, Some(&mut world));
            assert_eq!(s.grab(), None, "{button:?} at {at:?}");
            assert_eq!(s.camera, start, "{button:?} at {at:?}");
            // It orbits instead, and the box stays where it is.
            s.cursor_moved((at.0 + 40.0, at.1), Some(&mut world));
            assert!(s.camera.yaw != start.yaw, "{button:?} at {at:?}");
            for _ in 0..30 {
                world.step();
            }
            assert!(world.pose(cube).unwrap().position.y.abs() < 0.01);
        }
    }

    #[test]
    fn with_no_world_a_left_drag_orbits() {
        // The particle demo's window: nothing to pick, so the left button turns the camera.
        let mut s = state();
        let start = s.camera;
        s.mouse_button(MouseButton::Left, true, ON_THE_BOX, None);
        assert_eq!(s.grab(), None);
        s.cursor_moved((ON_THE_BOX.0 + 40.0, ON_THE_BOX.1), None);
        assert!(s.camera.yaw != start.yaw);
        let turned = s.camera;
        s.mouse_button(MouseButton::Left, false, ON_THE_BOX, None);
        s.cursor_moved((ON_THE_BOX.0 + 80.0, ON_THE_BOX.1), None);
        assert_eq!(s.camera, turned);
    }

    #[test]
    fn reset_lets_go_of_the_dragged_body() {
        let (mut world, _) = scene();
        let mut s = state();
        s.mouse_button(MouseButton::Left, true, ON_THE_BOX, Some(&mut world));
        assert!(s.grab().is_some());
        assert_eq!(s.key(Key::Space), Action::Reset);
        assert_eq!(s.grab(), None);
    }

    #[test]
    fn other_keys_change_nothing() {
        assert_eq!(press(Key::Char('7')), (Action::None, state()));
    }
}
