"""`python -m lgs_jax fit`: the command line of `lgs_jax.train.FitConfig`, generated from its
fields (`options`): an option per field of FitConfig and of its `Recipe`, named after the field;
`--strategy NAME` (`train.STRATEGIES`; default: the recipe's, `train.recipes`) with an option
per field of the strategies (default: the chosen strategy's own). The names that are not the
fields' are in one place: `ALIASES` (older options, still read), `DERIVED` (a field set from
another option), `CLI_ONLY` (options that are not configuration).
"""

from __future__ import annotations

import dataclasses
import json
import shlex

from . import options, view as view_cmd
from .args import UsageError, check_dataset, int_at_least, port

ALIASES = {"--no-compile-ahead": ("compile_ahead", "off"),  # older options: flag -> (field,
           "--compile-ahead-process": ("compile_ahead", "process")}  # value they set)
DERIVED = {"cap_max": "max_gaussians"}  # strategy field -> the FitConfig field it takes
CLI_ONLY = ("--viewer-port", "--viewer-host", "--debug", "--coordinator", "--num-processes",
            "--process-id")  # not configuration


def config_options() -> list:
    """The options of FitConfig's fields and its Recipe's (not the strategy's)."""
    from ..train import FitConfig, Recipe

    return options.fields_of(FitConfig, nested=(Recipe,), skip=("strategy",))


def strategy_options() -> list:
    """An option per field of the strategies of `train.STRATEGIES` (the first declaring it
    gives its type and help), `DERIVED` fields left out."""
    from ..train import STRATEGIES

    found = {}
    for cls in STRATEGIES.values():
        for f in dataclasses.fields(cls):
            if f.name not in DERIVED and f.name not in found:
                found[f.name] = options.Option(options.flag_of(f), ("strategy", f.name), f, cls)
    return list(found.values())


def _strategy_help(o: options.Option) -> str:
    from ..train import STRATEGIES

    has = [f"{name} {getattr(cls(), o.dest)}" for name, cls in STRATEGIES.items()
           if o.dest in {f.name for f in dataclasses.fields(cls)}]
    text = f"{o.field.metadata.get('help', '')} (strategy default: {', '.join(has)})"
    return text.replace("%", "%%")


def parser(sub, common) -> None:
    """The `fit` subcommand's options."""
    from ..train import STRATEGIES, FitConfig

    f = sub.add_parser(
        "fit", parents=[common], help="train Gaussians on a capture (COLMAP, transforms.json, "
                                      "NeRF-synthetic) with densification",
        description="Train Gaussians on a dataset (lgs_jax.load_dataset: every 8th image held "
                    "out, NeRF-synthetic ids 0,10,..,90) with gsplat's recipe and a densification "
                    "strategy. Writes into OUT: metrics.jsonl, checkpoints (resume continues "
                    "bit-identically), scene.ply (INRIA PLY), heldout_*.png (render beside ground "
                    "truth), curves.png, result.json. Ctrl-C stops after the current step, "
                    "writes a checkpoint and prints the command that resumes (exit code 130).")
    groups = options.add(f, config_options())
    strategy = next(x for x in dataclasses.fields(FitConfig) if x.name == "strategy")
    f.add_argument("--strategy", choices=list(STRATEGIES), default=None,
                   help=strategy.metadata["help"])
    for o in strategy_options():
        kw = options.argument(o.type, o.field, None)
        f.add_argument(o.flag, dest=o.dest, **dict(kw, help=_strategy_help(o)))
    for flag, (dest, value) in ALIASES.items():
        groups[dest].add_argument(flag, dest=dest, action="store_const", const=value,
                                  help=f"the same as --{dest.replace('_', '-')} {value}")
    f.add_argument("--viewer-port", type=port,
                   help="show the scene in training in a browser at this port (viser, "
                        "`pip install \"lgs_jax[viewer]\"`), updated about once a second, "
                        "and keep serving the trained scene after the run until Ctrl-C")
    f.add_argument("--viewer-host", default="0.0.0.0",
                   help="address the viewer listens on (default: all)")
    p = f.add_argument_group(
        "several processes", "one model trained by several processes (one per host, JAX's "
        "multi-controller model: jax.distributed.initialize), Gaussian parallel over every "
        "process's devices (--gaussian-devices: all of them unless given); run the same "
        "command on every process, --process-id its own; process 0 writes OUT, which every "
        "process must see for --resume (docs/multi-gpu.md)")
    p.add_argument("--coordinator", metavar="HOST:PORT",
                   help="process 0's address, where the processes meet")
    p.add_argument("--num-processes", type=int_at_least(1), help="how many processes")
    p.add_argument("--process-id", type=int_at_least(0), help="this process's index")
    f.set_defaults(func=run)


def _join(args) -> None:
    """With --coordinator: join the other processes (`jax.distributed.initialize`, before any
    other JAX work; on CPUs over gloo collectives). A usage error for an incomplete or
    inconsistent set of the three options."""
    given = [args.coordinator, args.num_processes, args.process_id]
    if all(v is None for v in given):
        return
    if any(v is None for v in given):
        raise UsageError("--coordinator, --num-processes and --process-id: give all three or "
                         "none")
    if args.process_id >= args.num_processes:
        raise UsageError(f"--process-id: must be below --num-processes ({args.num_processes}), "
                         f"got {args.process_id}")
    host, _, number = args.coordinator.rpartition(":")
    if not host or not number.isdigit():
        raise UsageError(f"--coordinator: expected HOST:PORT, got {args.coordinator!r}")
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # CPUs only; GPUs: NCCL
    jax.distributed.initialize(coordinator_address=args.coordinator,
                               num_processes=args.num_processes, process_id=args.process_id)


def _strategy(args, recipe: str):
    """The strategy --strategy names (default: recipe `recipe`'s) with the strategy options
    given (`DERIVED` fields from their options), or None (the recipe's, as `FitConfig` fills
    it in) where neither is given; a usage error for an option of another strategy."""
    from ..train import STRATEGIES
    from ..train.recipes import RUN_VALUES

    given = {o: getattr(args, o.dest) for o in strategy_options()
             if getattr(args, o.dest) is not None}
    if args.strategy is None and not given:
        return None
    name = args.strategy or RUN_VALUES[recipe]["strategy"]
    cls = STRATEGIES[name]
    names = {f.name for f in dataclasses.fields(cls)}
    for o in given:
        if o.dest not in names:
            raise UsageError(f"{o.flag}: the {name} strategy has no {o.dest}")
    values = {o.dest: value for o, value in given.items()}
    values.update({k: getattr(args, v) for k, v in DERIVED.items() if k in names})
    return cls(**values)


def config_of(args):
    """The `FitConfig` of parsed arguments; a usage error naming the option for a value the
    configuration refuses."""
    from ..train import FitConfig, Recipe

    top, recipe = {}, {}
    for path, value in options.values(args, config_options()).items():
        (recipe if path[0] == "recipe" else top)[path[-1]] = value
    try:
        return FitConfig(**top, recipe=Recipe(**recipe),
                         strategy=_strategy(args, recipe.get("name", "default")))
    except ValueError as e:
        field, _, message = str(e).partition(": ")
        raise UsageError(f"--{field.split('.')[-1].replace('_', '-')}: {message}") from None


def argv(config) -> list[str]:
    """The `fit` options that make `config` (`config_of` of them gives it back); ValueError
    for a configuration the command line cannot express (a strategy of another class, a
    `DERIVED` field unlike its option)."""
    from ..train import STRATEGIES, FitConfig, Recipe
    from ..train.recipes import RUN_VALUES

    # the values the recipe fills in where the options are not given
    usual = FitConfig(data="", out="", recipe=Recipe(name=config.recipe.name),
                      max_gaussians=config.max_gaussians)
    words = []
    for o in config_options():
        value, default = config, usual
        for name in o.path:
            value, default = getattr(value, name), getattr(default, name)
        words += options.argv(value, o, default if o.field.default is None else o.field.default)
    names = [n for n, cls in STRATEGIES.items() if type(config.strategy) is cls]
    if not names:
        raise ValueError(f"strategy: {type(config.strategy).__name__} has no command-line name")
    cls = STRATEGIES[names[0]]
    if names[0] != RUN_VALUES[config.recipe.name]["strategy"]:
        words += ["--strategy", names[0]]
    for o in strategy_options():
        if o.dest in {f.name for f in dataclasses.fields(cls)}:
            words += options.argv(getattr(config.strategy, o.dest), o,
                                  getattr(cls(), o.dest))
    for field, source in DERIVED.items():
        if hasattr(config.strategy, field) and \
                getattr(config.strategy, field) != getattr(config, source):
            raise ValueError(f"strategy.{field}: the command line sets it to {source}")
    return words


def resume_command(config) -> str:
    """The command that resumes `config`'s run (or a note where the command line cannot say
    it)."""
    try:
        words = argv(dataclasses.replace(config, resume=True, overwrite=False))
    except ValueError as e:
        return f"fit(dataclasses.replace(config, resume=True)) ({e})"
    return "python -m lgs_jax fit " + shlex.join(words)


def _stopped(config, e: KeyboardInterrupt) -> str:
    """What a Ctrl-C left: the step of OUT's checkpoint and the command that resumes it."""
    import os

    from .. import train

    if isinstance(e, train.Interrupted):
        step = e.step
    else:  # a second Ctrl-C, or one outside the steps: the last checkpoint written
        try:
            with open(os.path.join(config.out, "checkpoint.json")) as f:
                step = json.load(f)["step"]
        except (OSError, ValueError, KeyError):
            return f"interrupted before {config.out} held a checkpoint"
    return (f"stopped after step {step} of {config.steps}; the checkpoint in {config.out} "
            f"resumes it:\n  {resume_command(config)}")


def run(args) -> int:
    """`fit`: the configuration and OUT checked before any work, then train; Ctrl-C: exit 130
    with the command that resumes."""
    import sys

    from .. import train

    config = config_of(args)
    check_dataset(config.data)
    if config.precision == "float64":  # before any JAX work (`train.Setup` checks it)
        import jax

        jax.config.update("jax_enable_x64", True)
    _join(args)
    if args.coordinator is None:
        try:
            train.check_out(config, config.data)
        except train.RunDirError as e:
            raise UsageError(f"--{e.field.replace('_', '-')}: {e.message}") from None
    else:  # `fit` checks OUT on process 0 and tells every process its verdict
        import jax

        if config.gaussian_devices == 1:  # the one mesh that several processes train on
            config = dataclasses.replace(config, gaussian_devices=jax.device_count())
    data, watch, served = None, None, None
    if args.viewer_port is not None:
        from ..io.datasets import load_dataset

        data = load_dataset(config.data, downscale=config.downscale,
                            dtype=config.image_dtype)
        watch, served = view_cmd.training_viewer(args, config, data)
    try:
        result = train.fit(config, data, watch=watch)
    except BaseException as e:
        if served is not None:
            served.stop()  # the viewer's threads would keep the process alive
        if isinstance(e, train.RunDirError):  # another fit took OUT meanwhile
            raise UsageError(f"--{e.field.replace('_', '-')}: {e.message}") from None
        if not isinstance(e, KeyboardInterrupt):
            raise
        again = (" (on every process, each with its own --coordinator, --num-processes and "
                 "--process-id)" if args.coordinator is not None else "")
        print("\n" + _stopped(config, e) + again, file=sys.stderr)
        return 130
    print(json.dumps(result, indent=1))
    if served is not None:
        from ..viewer import wait

        print("training done; the viewer shows the trained scene (Ctrl-C stops)", flush=True)
        wait(served)
    return 0
