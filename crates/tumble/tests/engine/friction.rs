//! Coulomb friction against closed forms: a block on an incline sticks or slides at
//! g(sin θ − μ cos θ); a block sliding at v0 stops after v0² / (2 μ g); on the CPU and with
//! every stage on the GPU.
use crate::common;
use common::*;
use tumble::math::{Quat, Vec3};
use tumble::{BodyDesc, Shape, World};

/// A 20° incline (a plane through the origin) with a box resting on it; returns the distance
/// the box travelled down the slope after `seconds`, and the acceleration measured on the way
/// (every stage on the GPU when `gpu`).
fn incline(friction: f32, seconds: f32, gpu: bool) -> (f32, f32) {
    let angle = 20f32.to_radians();
    let tilt = Quat::from_rotation_z(angle);
    let mut world = World::new(awake_config()).unwrap();
    world
        .add_body(
            BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))
                .rotation(tilt)
                .friction(friction),
        )
        .unwrap();
    let normal = tilt * Vec3::Y;
    let start = normal * 0.5;
    let body = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                .position(start)
                .rotation(tilt)
                .friction(friction),
        )
        .unwrap();
    let _turn = on_gpu(&mut world, gpu);
    run(&mut world, seconds);
    let travelled = (world.pose(body).unwrap().position - start).length();
    // Distance from rest under constant acceleration: d = a t² / 2.
    (travelled, 2.0 * travelled / (seconds * seconds))
}

fn box_on_incline_sticks_with_high_friction(gpu: bool) {
    // tan 20° = 0.364 < 0.6: static friction holds.
    let (travelled, _) = incline(0.6, 3.0, gpu);
    assert!(travelled < 5e-3, "slid {travelled} m");
}

#[test]
fn box_on_incline_sticks_with_high_friction_on_the_cpu() {
    box_on_incline_sticks_with_high_friction(false);
}

#[test]
fn box_on_incline_sticks_with_high_friction_on_the_gpu() {
    box_on_incline_sticks_with_high_friction(true);
}

fn box_on_incline_slides_with_low_friction_at_the_closed_form_rate(gpu: bool) {
    let angle = 20f32.to_radians();
    let expected = G * (angle.sin() - 0.1 * angle.cos());
    let (_, acceleration) = incline(0.1, 2.0, gpu);
    let error = (acceleration - expected).abs() / expected;
    // The issue asks for 10%; 5% is kept because a square friction pyramid (19% too much
    // friction diagonally) passed at 10%.
    assert!(
        error < 0.05,
        "a = {acceleration}, expected {expected} (error {:.1}%)",
        100.0 * error
    );
}

#[test]
fn box_on_incline_slides_with_low_friction_at_the_closed_form_rate_on_the_cpu() {
    box_on_incline_slides_with_low_friction_at_the_closed_form_rate(false);
}

#[test]
fn box_on_incline_slides_with_low_friction_at_the_closed_form_rate_on_the_gpu() {
    box_on_incline_slides_with_low_friction_at_the_closed_form_rate(true);
}

fn sliding_box_stops_after_the_closed_form_distance_in_any_direction(gpu: bool) {
    let mu = 0.5;
    let v0 = 5.0;
    let expected = v0 * v0 / (2.0 * mu * G);
    // Along an axis and diagonally to the friction directions: friction must be isotropic.
    for direction in [
        Vec3::X,
        Vec3::new(1.0, 0.0, 1.0).normalize(),
        Vec3::new(-0.3, 0.0, 0.95).normalize(),
    ] {
        let mut world = world_with_ground(mu, 0.0);
        let start = Vec3::new(0.0, 0.5, 0.0);
        let body = world
            .add_body(
                BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                    .position(start)
                    .friction(mu)
                    .linear_velocity(direction * v0),
            )
            .unwrap();
        let _turn = on_gpu(&mut world, gpu);
        run(&mut world, 2.0);
        let travelled = (world.pose(body).unwrap().position - start).length();
        let error = (travelled - expected).abs() / expected;
        assert!(
            error < 0.05,
            "{direction}: stopped after {travelled} m, expected {expected} m"
        );
        assert!(
            world.linear_velocity(body).unwrap().length() < 1e-3,
            "box still moving"
        );
    }
}

#[test]
fn sliding_box_stops_after_the_closed_form_distance_in_any_direction_on_the_cpu() {
    sliding_box_stops_after_the_closed_form_distance_in_any_direction(false);
}

#[test]
fn sliding_box_stops_after_the_closed_form_distance_in_any_direction_on_the_gpu() {
    sliding_box_stops_after_the_closed_form_distance_in_any_direction(true);
}
