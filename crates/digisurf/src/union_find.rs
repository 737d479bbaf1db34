//! The find of a union-find forest over `u32` ids, shared by the components and pinch
//! splits here and by the crates above.

/// The root of `x` in the union-find forest `parent` (each id's parent, a root its own),
/// halving the path on the way: each id visited is re-parented to its grandparent.
/// Linking stays with the caller, whose rule (the smaller root, the first root) decides
/// which id a component's root is.
pub fn union_find_root(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let up = parent[parent[x as usize] as usize];
        parent[x as usize] = up;
        x = up;
    }
    x
}
