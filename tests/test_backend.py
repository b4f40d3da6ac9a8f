"""Backend selection: libLLVM discovery, variant choice, thread settings."""

import pytest

from dpi.render import backend


def test_llvm_major_parses_debian_and_versioned_names():
    assert backend.llvm_major("/usr/lib/x86_64-linux-gnu/libLLVM-19.so") == 19
    assert backend.llvm_major("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1") == 19
    assert backend.llvm_major("/usr/lib/llvm-17/lib/libLLVM.so") == 17


def test_find_libllvm_prefers_newest_usable(tmp_path):
    for name in ("libLLVM-14.so", "libLLVM-16.so", "libLLVM-19.so"):
        (tmp_path / name).touch()
    assert backend.find_libllvm((str(tmp_path / "libLLVM-*.so"),)).endswith("libLLVM-19.so")


def test_no_usable_llvm_is_one_clear_error(tmp_path, monkeypatch):
    (tmp_path / "libLLVM-14.so").touch()
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    monkeypatch.setattr(backend, "LLVM_SEARCH_GLOBS", (str(tmp_path / "libLLVM-*.so"),))
    with pytest.raises(backend.BackendError, match="libllvm19"):
        backend.configure_llvm()


def test_unknown_variant_is_rejected():
    with pytest.raises(backend.BackendError, match="unknown Mitsuba variant"):
        backend.choose_variant("scalar_spectral")


def test_cpu_machine_gets_llvm_variant_and_thread_count(mi):
    import drjit as dr
    import torch

    assert mi.variant() == ("cuda_ad_rgb" if torch.cuda.is_available() else "llvm_ad_rgb")
    backend.set_threads(1)
    assert torch.get_num_threads() == 1 and dr.thread_count() == 1
    backend.set_threads(2)
    assert torch.get_num_threads() == 2 and dr.thread_count() == 2
