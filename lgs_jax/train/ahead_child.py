"""The child process of `ahead.Stepper`'s mode "process": reads JAX settings, then (lower,
abstract arguments, size), pickled on stdin; applies the settings before anything else is
unpickled and compiles `lower(abstract, size)`, which stores the executable in JAX's
persistent compilation cache for the parent.

    python -m lgs_jax.train.ahead_child < payload
"""

import pickle
import sys

import jax


def main() -> None:
    for name, value in pickle.load(sys.stdin.buffer).items():
        jax.config.update(name, value)
    lower, abstract, size = pickle.load(sys.stdin.buffer)
    lower(abstract, size).compile()


if __name__ == "__main__":
    main()
