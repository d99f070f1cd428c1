"""The child process of `ahead.Stepper`'s mode "process": reads JAX settings, then (module,
name, abstract arguments, static arguments), pickled on stdin; applies the settings before
anything else is unpickled, imports the jitted function by its module and name and compiles
`fn.lower(*abstract, **static)`, which stores the executable in JAX's persistent compilation
cache for the parent.

    python -m lgs_jax.train.ahead_child < payload
"""

import functools
import importlib
import pickle
import sys

import jax


def main() -> None:
    for name, value in pickle.load(sys.stdin.buffer).items():
        jax.config.update(name, value)
    module, name, abstract, static = pickle.load(sys.stdin.buffer)
    try:
        fn = functools.reduce(getattr, name.split("."), importlib.import_module(module))
    except AttributeError:
        sys.exit(f"{module}.{name}: not a module-level function, which the child imports")
    fn.lower(*abstract, **static).compile()


if __name__ == "__main__":
    main()
