from vecontact.cli import main

raise SystemExit(main())
