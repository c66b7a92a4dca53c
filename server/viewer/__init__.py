"""The live 3D view (viser): the selected run's scene and panel, and replay of episodes."""

from server.viewer.app import Viewer

__all__ = ["Viewer"]
