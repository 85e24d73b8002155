from motorlab.cli import main

main()
