use bevy_marble::prelude::*;
fn main() {
    let s = Scene::from_ron_str("(dt: 0.016666668, boards: [(shape: HeightField(heights: [[0.0,0.0,0.0,0.0],[0.0,0.0,0.0,0.0],[0.0,0.0,0.0,0.0],[0.0,0.0,0.0,0.0]], scale: (2.0,1.0,2.0)))], marbles: [(position: (0.0, 0.008, 0.0))])").unwrap();
    let mut sim = Simulation::from_scene(&s).unwrap();
    for _ in 0..2 {
        sim.step();
        let m = sim.marbles()[0];
        println!("{:?}", sim.marble_state(0));
        for c in sim.world().get::<Contacts>(m).unwrap().iter() {
            println!("{c:?}");
        }
    }
}
