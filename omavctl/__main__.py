from omavctl.cli import main

main()
