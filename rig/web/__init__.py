"""The control page: a FastAPI app over the engine and the store (docs/web.md).

``create_app(settings, controller)`` builds the app; ``rig serve`` runs it with uvicorn.
"""

from rig.web.app import create_app
from rig.web.settings import WebSettings

__all__ = ["WebSettings", "create_app"]
