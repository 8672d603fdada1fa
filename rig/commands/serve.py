"""``rig serve``: the control page (FastAPI + uvicorn) over the simulated or a real rig."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from rig.commands.options import SamplesOption


def register(app: typer.Typer) -> None:
    @app.command(short_help="Serve the control page.")
    def serve(
        simulated: Annotated[bool, typer.Option(
            "--simulated", help="Start the simulated rig (its own process) and serve it.")] = False,
        rig: Annotated[Path | None, typer.Option(
            "--rig", help="A rig configuration TOML (a real rig).")] = None,
        host: Annotated[str, typer.Option(
            help="Address to listen on. Other than 127.0.0.1 needs --token.")] = "127.0.0.1",
        port: Annotated[int, typer.Option(
            min=0, max=65535, help="Port (0: a free one, printed).")] = 8765,
        store: Annotated[str | None, typer.Option(
            help="Measurement store: a folder or a database URL postgresql://... "
                 "(default: $RIG_STORE or ./rig-store).")] = None,
        samples: SamplesOption = None,
        token: Annotated[str | None, typer.Option(
            help="Operator token (default: $RIG_WEB_TOKEN, else the store's token file, "
                 "else generated and printed).")] = None,
        unit: Annotated[str, typer.Option(
            help="With --simulated: the example unit (rig/examples/units) the simulated "
                 "plant is built from.")] = "seed000-pair1",
        plant: Annotated[Path | None, typer.Option(
            "--plant", help="With --simulated: a plant TOML the simulated rig runs with `rig "
                            "sim --config` instead of the --unit plant (simulators/"
                            "cycloid_plant.toml, beveloid_plant.toml: docs/unit-kinds.md).")
        ] = None,
    ) -> None:
        """Serve the control page: devices, plans, live loop, E-stop, results, history.

        Prints the page's address and the operator token; stops on Ctrl-C (the rig is left
        in its safe state).
        """
        from rig.core.errors import RigError
        from rig.core.process_exit import prepare_exit
        from rig.store import Store, default_store_root
        from rig.web.app import create_app
        from rig.web.engine_host import EngineHost, EngineSpec
        from rig.web.live import LiveHub
        from rig.web.server import StoreServedAlready, bind, claim_store, uvicorn_server
        from rig.web.settings import resolve_settings
        from rig.web.simulated import example_unit, simulated_plant

        if simulated == (rig is not None):
            raise RigError("say which rig: --simulated (start the simulated rig) or --rig FILE "
                           "(a rig configuration)")
        root = store if store is not None else default_store_root()
        the_store = Store(root, samples=samples)
        if the_store.backend == "sqlite":  # a database store is shared by every rig's page
            try:
                claim_store(the_store.root)  # its descriptor stays open: held until the end
            except StoreServedAlready as exc:
                raise RigError(str(exc)) from None
        settings = resolve_settings(host, port, store_root=the_store.root, token=token,
                                    check_host=True)
        hub = LiveHub()
        if plant is not None and not simulated:
            raise RigError("--plant is the simulated rig's plant: give it with --simulated")
        if plant is not None:
            kind = simulated_plant(str(plant)).unit.get("kind", "internal_involute")
            description = f"simulated rig (plant: {plant.name}, unit kind {kind})"
        elif simulated:
            example_unit(unit)  # an unknown unit is refused here, before anything starts
            description = f"simulated rig (plant: example unit {unit})"
        else:
            description = f"rig {rig}"
        # The rig runs in the engine's own process (rig/web/engine_host.py): no page request,
        # SSE client or analysis of this server can hold up its keepalive or acquisition.
        controller = EngineHost(EngineSpec(
            store=str(root), samples=None if samples is None else str(samples),
            simulated_unit=unit if simulated else None,
            simulated_plant=None if plant is None else str(plant.resolve()),
            rig_path=None if rig is None else str(rig), description=description), the_store, hub)
        web_app = create_app(settings, controller)

        try:
            sock = bind(host, port)
        except OSError as exc:
            raise RigError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from exc
        bound = sock.getsockname()[1]
        url = settings.url.replace(f":{port}/", f":{bound}/")
        token_file = the_store.root / "web" / "operator-token"
        where = {"option": "from --token", "environment": "from $RIG_WEB_TOKEN",
                 "file": f"from {token_file}",
                 "generated": f"generated; kept in {token_file}"}
        print(f"control page: {url}", flush=True)
        print(f"operator token: {settings.token} ({where[settings.token_source]})", flush=True)
        print(f"operator link: {url}#token={settings.token}", flush=True)
        print(f"store: {the_store.root}; {description}; Ctrl-C stops (the rig is left safe)",
              file=sys.stderr, flush=True)
        try:
            uvicorn_server(web_app).run(sockets=[sock])
        finally:  # the rig is closed (the lifespan's end): exit without a slow teardown
            prepare_exit()
