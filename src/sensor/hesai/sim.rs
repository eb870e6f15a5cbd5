//! Hesai packet encoder (points → byte-exact packets): used by tests and the simulator.
