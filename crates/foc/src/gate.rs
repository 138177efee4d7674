//! Parts left out by a cargo feature: [`Absent`], a stand-in type that has no value.
//!
//! A part the controller holds as an `Option` (HFI) is held, when its feature is off, as an
//! `Option<Absent<T>>`: always `None`, and the compiler knows it, so every branch that works
//! on the part is removed from the build. With the feature on the alias is `T` itself and
//! nothing changes (the module is not even compiled).

use core::convert::Infallible;
use core::fmt;
use core::marker::PhantomData;
use core::ops::{Deref, DerefMut};

/// A `T` that cannot exist: no value of this type can be made, so `Option<Absent<T>>` is
/// always `None` and code that would use the `T` is dead. It dereferences to `T` (never
/// called) so that the code using the part compiles unchanged.
pub(crate) struct Absent<T> {
    never: Infallible,
    part: PhantomData<T>,
}

impl<T> Clone for Absent<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Absent<T> {}

impl<T> fmt::Debug for Absent<T> {
    fn fmt(&self, _: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.never {}
    }
}

impl<T> Deref for Absent<T> {
    type Target = T;
    fn deref(&self) -> &T {
        let _ = self.part;
        match self.never {}
    }
}

impl<T> DerefMut for Absent<T> {
    fn deref_mut(&mut self) -> &mut T {
        match self.never {}
    }
}
