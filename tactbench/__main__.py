from tactbench.cli import main

main()
