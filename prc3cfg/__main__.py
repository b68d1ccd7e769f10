"""The entry point of `prc3cfg` and `python -m prc3cfg`: signals are handled first of all
(`prc3cfg.shell.cancel.exit_on_signal`), then the command line is imported and run — a Ctrl-C
while Python imports it is one line and exit 130 like any other."""

from prc3cfg.shell.cancel import exit_on_signal


def main() -> None:
    exit_on_signal()
    from prc3cfg.cli import main as run

    run()


if __name__ == "__main__":
    main()
