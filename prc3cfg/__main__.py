from prc3cfg.cli import main

main()
