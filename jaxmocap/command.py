"""The ``jaxmocap`` command's entry point: its process's settings (`xla_options.configure_process`) before anything
loads NumPy's or SciPy's OpenBLAS or starts JAX, then the command line (`cli.main`). Importing the package, or
`cli`, changes nothing in a process."""


def main(argv=None) -> int:
    from jaxmocap.xla_options import configure_process

    configure_process()
    from jaxmocap.cli import main as cli_main

    return cli_main(argv)
