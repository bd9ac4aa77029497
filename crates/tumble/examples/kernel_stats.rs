//! What the driver made of each kernel a scene runs: registers, spills, shared memory and
//! whatever else it reports through `VK_KHR_pipeline_executable_properties`. A kernel bound
//! by latency with a thread per constraint (the solver's) runs as many threads at once as its
//! registers allow, which wgpu cannot tell.
//!
//! ```text
//! cargo run --release -p tumble --example kernel_stats -- [SCENE [STEPS [FILTER]]]
//! ```
//!
//! SCENE is a built-in scene or a scene file (default falling-boxes), stepped STEPS times
//! (default 3) with every stage on the GPU, which compiles the kernels it needs; FILTER keeps
//! the kernels whose label or entry point contains it. Each kernel is then compiled again
//! outside wgpu: naga writes SPIR-V with the options wgpu's Vulkan backend uses on a device
//! with `robustBufferAccess2` (the index bounds clamped, buffer accesses left to the driver,
//! loops bounded), and a Vulkan device of the same adapter, made with the extension, reports
//! its statistics. STATS_DEVICE names another device to ask instead (part of its name): on a
//! machine without a GPU, `RADV_FORCE_FAMILY=navi21 TUMBLE_ADAPTER=llvmpipe STATS_DEVICE=RADV`
//! runs the scene on lavapipe and has Mesa's RADV compile for an AMD chip it does not have.

use std::ffi::CStr;
use std::path::Path;
use std::process::ExitCode;

use ash::vk;
use tumble::gpu::GpuContext;
use tumble::gpu::kernel::KernelSource;
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::Scene;
use tumble::scene::builtin::builtin;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("kernel_stats: {error}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_name = args.first().map_or("falling-boxes", String::as_str);
    let steps: u32 = match args.get(1) {
        Some(steps) => steps
            .parse()
            .map_err(|_| format!("bad step count {steps:?}"))?,
        None => 3,
    };
    let filter = args.get(2).map_or("", String::as_str);
    let scene = if Path::new(scene_name).exists() {
        Scene::load(Path::new(scene_name)).map_err(|e| e.to_string())?
    } else {
        builtin(scene_name, 1.0).map_err(|e| e.to_string())?
    };
    let context = GpuContext::shared().map_err(|e| e.to_string())?;
    // Another device may compile the kernels than the one that ran the scene: Mesa's RADV
    // without a GPU (RADV_FORCE_FAMILY=navi21), say, on a machine whose wgpu runs lavapipe.
    let stats_device = std::env::var("STATS_DEVICE").unwrap_or_else(|_| context.info.name.clone());
    context.record_kernel_sources();
    let mut world = scene.build().map_err(|e| e.to_string())?;
    world
        .set_stage_devices(StageDevices::all(Executor::Gpu))
        .map_err(|e| e.to_string())?;
    for _ in 0..steps {
        world.try_step().map_err(|e| e.to_string())?;
    }
    let sources: Vec<KernelSource> = context
        .kernel_sources()
        .into_iter()
        .filter(|k| k.label.contains(filter) || k.entry.contains(filter))
        .collect();
    println!(
        "{} kernels of {scene_name} on {}",
        sources.len(),
        context.describe()
    );
    // SAFETY: every Vulkan object made here is destroyed before the device, and the device
    // before the instance (Driver::drop).
    let driver = unsafe { Driver::new(&stats_device) };
    if let Err(why) = &driver {
        println!("{why}: the SPIR-V sizes alone");
    }
    for kernel in &sources {
        let (module, info) = module(kernel)?;
        let words = spirv(kernel, &module, &info)?;
        let stats = match &driver {
            // SAFETY: `words` is valid SPIR-V from naga's validated module.
            Ok(driver) => unsafe {
                driver.statistics(&words, &bindings(kernel, &module)?, &kernel.entry)?
            },
            Err(_) => vec![format!("spirv_words={}", words.len())],
        };
        println!("{} / {}: {}", kernel.label, kernel.entry, stats.join(", "));
    }
    Ok(())
}

/// The kernel's module, parsed and validated, with its analysis.
fn module(kernel: &KernelSource) -> Result<(naga::Module, naga::valid::ModuleInfo), String> {
    let module = naga::front::wgsl::parse_str(&kernel.wgsl)
        .map_err(|e| format!("{}: {}", kernel.label, e.emit_to_string(&kernel.wgsl)))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| format!("{}: {}", kernel.label, e.emit_to_string(&kernel.wgsl)))?;
    Ok((module, info))
}

/// SPIR-V of the kernel's entry point, written as wgpu's Vulkan backend writes it.
fn spirv(
    kernel: &KernelSource,
    module: &naga::Module,
    info: &naga::valid::ModuleInfo,
) -> Result<Vec<u32>, String> {
    use naga::proc::{BoundsCheckPolicies, BoundsCheckPolicy};
    let options = naga::back::spv::Options {
        lang_version: (1, 5),
        bounds_check_policies: BoundsCheckPolicies {
            index: BoundsCheckPolicy::Restrict,
            buffer: BoundsCheckPolicy::Unchecked,
            image_load: BoundsCheckPolicy::Unchecked,
            binding_array: BoundsCheckPolicy::Unchecked,
        },
        zero_initialize_workgroup_memory:
            naga::back::spv::ZeroInitializeWorkgroupMemoryMode::Native,
        force_loop_bounding: true,
        // Bindings as written: group 0 is set 0, as wgpu lays them out.
        fake_missing_bindings: true,
        ..Default::default()
    };
    let pipeline = naga::back::spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: kernel.entry.clone(),
    };
    naga::back::spv::write_vec(module, info, &options, Some(&pipeline))
        .map_err(|e| format!("{} / {}: {e}", kernel.label, kernel.entry))
}

/// The descriptor type of each binding of group 0, by binding number.
fn bindings(
    kernel: &KernelSource,
    module: &naga::Module,
) -> Result<Vec<(u32, vk::DescriptorType)>, String> {
    let mut out = Vec::new();
    for (_, variable) in module.global_variables.iter() {
        let Some(binding) = &variable.binding else {
            continue;
        };
        let kind = match variable.space {
            naga::AddressSpace::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
            naga::AddressSpace::Storage { .. } => vk::DescriptorType::STORAGE_BUFFER,
            other => return Err(format!("{}: binding in {other:?}", kernel.label)),
        };
        if binding.group != 0 {
            return Err(format!("{}: a binding outside group 0", kernel.label));
        }
        out.push((binding.binding, kind));
    }
    Ok(out)
}

/// A Vulkan device of the adapter named like wgpu's, made with the extension.
struct Driver {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    executables: ash::khr::pipeline_executable_properties::Device,
}

impl Driver {
    unsafe fn new(adapter: &str) -> Result<Self, String> {
        let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader: {e}"))?;
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
        let instance = unsafe {
            entry.create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )
        }
        .map_err(|e| format!("vkCreateInstance: {e}"))?;
        let physical = unsafe { instance.enumerate_physical_devices() }
            .map_err(|e| format!("vkEnumeratePhysicalDevices: {e}"))?
            .into_iter()
            .find(|&device| {
                let properties = unsafe { instance.get_physical_device_properties(device) };
                let name = properties.device_name_as_c_str().ok();
                name.and_then(|n| n.to_str().ok())
                    .is_some_and(|name| name.contains(adapter))
            })
            .ok_or_else(|| format!("no Vulkan device's name contains {adapter:?}"))?;
        let extensions = unsafe { instance.enumerate_device_extension_properties(physical) }
            .map_err(|e| format!("vkEnumerateDeviceExtensionProperties: {e}"))?;
        let has = |name: &CStr| {
            extensions
                .iter()
                .any(|e| e.extension_name_as_c_str() == Ok(name))
        };
        let wanted = ash::khr::pipeline_executable_properties::NAME;
        if !has(wanted) {
            return Err(format!("{adapter} does not report pipeline statistics"));
        }
        // Every feature the device has, as wgpu asks for most of them (robustness above all,
        // which decides how buffer accesses are compiled).
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default();
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
        let mut robustness = vk::PhysicalDeviceRobustness2FeaturesEXT::default();
        let mut features = vk::PhysicalDeviceFeatures2::default()
            .push_next(&mut v11)
            .push_next(&mut v12)
            .push_next(&mut v13);
        let has_robustness = has(ash::ext::robustness2::NAME);
        if has_robustness {
            features = features.push_next(&mut robustness);
        }
        unsafe { instance.get_physical_device_features2(physical, &mut features) };
        let core = features.features;
        let mut executable = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default()
            .pipeline_executable_info(true);
        let mut names = vec![wanted.as_ptr()];
        // The queried structs, unchained, are what the device enables.
        v11.p_next = std::ptr::null_mut();
        v12.p_next = std::ptr::null_mut();
        v13.p_next = std::ptr::null_mut();
        let mut robustness = vk::PhysicalDeviceRobustness2FeaturesEXT::default()
            .robust_buffer_access2(robustness.robust_buffer_access2 != 0);
        let mut enabled = vk::PhysicalDeviceFeatures2::default()
            .features(core)
            .push_next(&mut v11)
            .push_next(&mut v12)
            .push_next(&mut v13)
            .push_next(&mut executable);
        if has_robustness {
            names.push(ash::ext::robustness2::NAME.as_ptr());
            enabled = enabled.push_next(&mut robustness);
        }
        let priorities = [1.0];
        let queue = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(0)
            .queue_priorities(&priorities)];
        let info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue)
            .enabled_extension_names(&names)
            .push_next(&mut enabled);
        let device = unsafe { instance.create_device(physical, &info, None) }
            .map_err(|e| format!("vkCreateDevice: {e}"))?;
        let executables = ash::khr::pipeline_executable_properties::Device::new(&instance, &device);
        Ok(Self {
            _entry: entry,
            instance,
            device,
            executables,
        })
    }

    /// "name=value" for each statistic of each executable of the compute pipeline.
    unsafe fn statistics(
        &self,
        words: &[u32],
        bindings: &[(u32, vk::DescriptorType)],
        entry: &str,
    ) -> Result<Vec<String>, String> {
        let device = &self.device;
        let vk_bindings: Vec<vk::DescriptorSetLayoutBinding> = bindings
            .iter()
            .map(|&(binding, kind)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(kind)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_layout = unsafe {
            device.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&vk_bindings),
                None,
            )
        }
        .map_err(|e| format!("vkCreateDescriptorSetLayout: {e}"))?;
        let set_layouts = [set_layout];
        let layout = unsafe {
            device.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts),
                None,
            )
        }
        .map_err(|e| format!("vkCreatePipelineLayout: {e}"))?;
        let module = unsafe {
            device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
        }
        .map_err(|e| format!("vkCreateShaderModule: {e}"))?;
        let name = std::ffi::CString::new(entry).map_err(|e| e.to_string())?;
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(&name);
        let info = vk::ComputePipelineCreateInfo::default()
            .flags(vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR)
            .stage(stage)
            .layout(layout);
        let pipelines =
            unsafe { device.create_compute_pipelines(vk::PipelineCache::null(), &[info], None) };
        let result = match pipelines {
            Ok(pipelines) => {
                let pipeline = pipelines[0];
                let stats = unsafe { self.pipeline_statistics(pipeline) };
                unsafe { device.destroy_pipeline(pipeline, None) };
                stats
            }
            Err((_, e)) => Err(format!("vkCreateComputePipelines: {e}")),
        };
        unsafe {
            device.destroy_shader_module(module, None);
            device.destroy_pipeline_layout(layout, None);
            device.destroy_descriptor_set_layout(set_layout, None);
        }
        result
    }

    unsafe fn pipeline_statistics(&self, pipeline: vk::Pipeline) -> Result<Vec<String>, String> {
        let info = vk::PipelineInfoKHR::default().pipeline(pipeline);
        let count = unsafe { self.executables.get_pipeline_executable_properties(&info) }
            .map_err(|e| format!("vkGetPipelineExecutablePropertiesKHR: {e}"))?
            .len();
        let mut out = Vec::new();
        for index in 0..count as u32 {
            let executable = vk::PipelineExecutableInfoKHR::default()
                .pipeline(pipeline)
                .executable_index(index);
            let stats = unsafe {
                self.executables
                    .get_pipeline_executable_statistics(&executable)
            }
            .map_err(|e| format!("vkGetPipelineExecutableStatisticsKHR: {e}"))?;
            for stat in stats {
                let name = stat
                    .name_as_c_str()
                    .map_or("?".into(), |n| n.to_string_lossy().into_owned());
                // SAFETY: `format` says which member of the union the driver wrote.
                let value = unsafe {
                    match stat.format {
                        vk::PipelineExecutableStatisticFormatKHR::BOOL32 => {
                            (stat.value.b32 != 0).to_string()
                        }
                        vk::PipelineExecutableStatisticFormatKHR::INT64 => {
                            stat.value.i64.to_string()
                        }
                        vk::PipelineExecutableStatisticFormatKHR::UINT64 => {
                            stat.value.u64.to_string()
                        }
                        _ => format!("{:.3}", stat.value.f64),
                    }
                };
                out.push(format!("{name}={value}"));
            }
        }
        Ok(out)
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        // SAFETY: every object made on the device was destroyed after its use.
        unsafe {
            self.device.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}
